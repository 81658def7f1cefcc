#!/usr/bin/python3
"""Reliability diagram of the loop probability pooled over sequences (scripts/bench_accuracy.sh).

Usage: plot_reliability.py OUTPUT.png RESULTS_DIR NAME=SEQUENCE_DIR [...]
RESULTS_DIR/NAME.csv are mild_offline's candidates; SEQUENCE_DIR/gt_loops.txt the ground truth.
Each query's best candidate counts (don't-care pairs skipped), as in EVALUATION.md. Sequences whose
name ends in _s203/_s204 or starts with scale are drawn as the hold-out set, the others as the
sequences the scorer was fitted on.
"""
import re
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402


def pairs(results, name, folder):
    truth, dc = set(), set()
    for line in open(f"{folder}/gt_loops.txt"):
        p = line.split()
        if len(p) >= 4 and not p[0].startswith("#"):
            (truth if p[3] == "1" else dc).add((int(p[0]), int(p[1])))
    best = {}
    for line in open(f"{results}/{name}.csv"):
        p = line.strip().split(",")
        if p[0] == "query" or int(p[0]) - int(p[1]) < 40:
            continue
        i, j, s = int(p[0]), int(p[1]), float(p[2])
        if i not in best or s > best[i][1]:
            best[i] = (j, s)
    return [(s, (i, j) in truth) for i, (j, s) in best.items() if (i, j) in truth or (i, j) not in dc]


def curve(scored, bins=10):
    s = np.array([v for v, _ in scored])
    r = np.array([ok for _, ok in scored], dtype=float)
    edges = np.linspace(0, 1, bins + 1)
    index = np.minimum((s * bins).astype(int), bins - 1)
    points, ece = [], 0.0
    for b in range(bins):
        m = index == b
        if m.sum() == 0:
            continue
        points.append((s[m].mean(), r[m].mean(), int(m.sum())))
        ece += m.sum() * abs(r[m].mean() - s[m].mean())
    return points, ece / max(1, len(s))


def main():
    if len(sys.argv) < 4:
        sys.exit(__doc__)
    out, results = sys.argv[1], sys.argv[2]
    groups = {"fitted on": [], "hold-out": []}
    for spec in sys.argv[3:]:
        name, folder = spec.split("=", 1)
        held = re.search(r"_s20[34]$", name) or name.startswith("scale")
        groups["hold-out" if held else "fitted on"] += pairs(results, name, folder)
    fig, ax = plt.subplots(figsize=(5, 4.2), dpi=120)
    ax.plot([0, 1], [0, 1], ":", color="grey", lw=1, label="calibrated")
    for (label, scored), colour in zip(groups.items(), ["tab:blue", "tab:orange"]):
        if not scored:
            continue
        points, ece = curve(scored)
        ax.plot([p[0] for p in points], [p[1] for p in points], "o-", color=colour,
                label=f"{label}: {len(scored)} queries, ECE {ece:.3f}")
        for x, y, n in points:
            ax.annotate(str(n), (x, y), textcoords="offset points", xytext=(4, -10), fontsize=6, color=colour)
    ax.set_xlim(0, 1)
    ax.set_ylim(0, 1.02)
    ax.set_xlabel("loop probability (bin mean)")
    ax.set_ylabel("fraction of best candidates that are right")
    ax.set_title("reliability of the loop probability (best candidate per query)", fontsize=9)
    ax.legend(loc="upper left", fontsize=7)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(out)


if __name__ == "__main__":
    main()
