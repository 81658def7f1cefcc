#!/usr/bin/python3
"""Plots for mild_offline: precision-recall curve, detections against ground truth, and the
reliability diagram of the loop probability.

Usage: plot_offline.py PLOT_DATA.json OUTPUT_DIR   (PLOT_DATA.json is written by mild_offline --plots)
"""
import json
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402


def pr_curve(data, path):
    curve = np.array(data.get("curve", []) or [[0, 1, 0]], dtype=float)
    fig, ax = plt.subplots(figsize=(5, 4), dpi=120)
    ax.plot(curve[:, 2], curve[:, 1], "-", color="tab:blue", lw=1.5)
    ax.set_xlim(0, 1.02)
    ax.set_ylim(0, 1.02)
    ax.set_xlabel("recall")
    ax.set_ylabel("precision")
    ax.set_title("recall@100%%P %.3f   AP %.3f   max F1 %.3f"
                 % (data["recall_at_100_precision"], data["average_precision"], data["max_f1"]), fontsize=9)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def loops_matrix(data, path):
    n = int(data["frames"])
    truth = {tuple(p) for p in data.get("truth", [])}
    dont_care = {tuple(p) for p in data.get("dont_care", [])}
    detections = data.get("detections", [])
    # Operating point: every best candidate scoring at least the lowest score reached with
    # precision still 100%.
    ranked = sorted(detections, key=lambda d: -d[2])
    threshold = float("inf")
    for q, c, s in ranked:
        if (q, c) not in truth and (q, c) not in dont_care:
            break
        threshold = s
    detected = [(q, c) for q, c, s in detections if s >= threshold]
    image = np.ones((n, n, 3))
    for i, j in dont_care:
        if i < n and j < n:
            image[i, j] = (1.0, 0.95, 0.75)
    for i, j in truth:
        if i < n and j < n:
            image[i, j] = (1.0, 0.82, 0.1)
    fig, ax = plt.subplots(figsize=(5.5, 5), dpi=120)
    ax.imshow(image, origin="upper", interpolation="nearest")
    right = np.array([(q, c) for q, c in detected if (q, c) in truth] or np.zeros((0, 2)))
    other = np.array([(q, c) for q, c in detected if (q, c) not in truth] or np.zeros((0, 2)))
    ax.scatter(right[:, 1], right[:, 0], s=6, color=(0.5, 0.25, 0.05), label="detected, in ground truth")
    ax.scatter(other[:, 1], other[:, 0], s=6, color=(0.85, 0.1, 0.1), label="detected, don't care")
    ax.plot([], [], "s", color=(1.0, 0.82, 0.1), label="ground truth")
    ax.set_xlim(-0.5, n - 0.5)
    ax.set_ylim(n - 0.5, -0.5)
    ax.set_xlabel("candidate frame j")
    ax.set_ylabel("query frame i")
    ax.set_title("detected closures at 100%% precision (score >= %.3g) vs ground truth" % threshold
                 if ranked else "no detections", fontsize=9)
    ax.legend(loc="upper right", fontsize=8)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def reliability(data, path):
    bins = data.get("reliability", [])
    fig, ax = plt.subplots(figsize=(5, 4), dpi=120)
    ax.plot([0, 1], [0, 1], ":", color="grey", lw=1, label="calibrated")
    used = [b for b in bins if b[2] > 0]
    if used:
        mean = [b[3] for b in used]
        right = [b[4] for b in used]
        ax.plot(mean, right, "o-", color="tab:blue", lw=1.5, label="best candidate per query")
        for b in used:
            ax.annotate(str(int(b[2])), (b[3], b[4]), textcoords="offset points", xytext=(4, -10), fontsize=7)
    d = data.get("decision", {})
    ax.axvline(d.get("threshold", 0.5), color="tab:red", lw=0.8, alpha=0.5)
    ax.set_xlim(0, 1)
    ax.set_ylim(0, 1.02)
    ax.set_xlabel("loop probability (bin mean)")
    ax.set_ylabel("fraction right")
    ax.set_title("reliability: ECE %.3f;  at the decision p >= %g: precision %.3f, recall %.3f"
                 % (data.get("expected_calibration_error", 0.0), d.get("threshold", 0.5), d.get("precision", 1.0),
                    d.get("recall", 0.0)),
                 fontsize=8)
    ax.legend(loc="upper left", fontsize=8)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def main():
    if len(sys.argv) != 3:
        sys.exit(__doc__)
    with open(sys.argv[1]) as f:
        data = json.load(f)
    pr_curve(data, f"{sys.argv[2]}/pr_curve.png")
    loops_matrix(data, f"{sys.argv[2]}/loops_matrix.png")
    reliability(data, f"{sys.argv[2]}/reliability.png")


if __name__ == "__main__":
    main()
