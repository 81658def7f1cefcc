#!/usr/bin/python3
"""Draws what mild_pose_graph_eval --plot wrote: ground truth, the drifted odometry and the
corrected trajectory (both aligned onto the truth), and the loop edges on the corrected one (green:
kept, red: rejected by the robust loss).
  plot_pose_graph.py TRAJECTORIES.csv LOOPS.csv OUT.png [--title TEXT]"""
import argparse
import csv

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("trajectories")
    ap.add_argument("loops")
    ap.add_argument("out")
    ap.add_argument("--title", default="")
    a = ap.parse_args()
    rows = list(csv.DictReader(open(a.trajectories)))
    col = {k: [float(r[k]) for r in rows] for k in rows[0] if k != "frame"}
    loops = list(csv.DictReader(open(a.loops)))
    fig, ax = plt.subplots(figsize=(7, 6), dpi=110)
    for kind, colour in ((1, "#2ca02c"), (0, "#d62728")):
        for lp in loops:
            if int(lp["inlier"]) != kind:
                continue
            q, c = int(lp["query"]), int(lp["candidate"])
            ax.plot([col["after_x"][q], col["after_x"][c]], [col["after_y"][q], col["after_y"][c]],
                    color=colour, lw=0.6, alpha=0.6 if kind else 0.9, zorder=1)
    ax.plot(col["true_x"], col["true_y"], color="black", lw=1.2, label="ground truth", zorder=2)
    ax.plot(col["odometry_x"], col["odometry_y"], color="#ff7f0e", lw=1.0, ls="--", label="odometry (drift)",
            zorder=3)
    ax.plot(col["after_x"], col["after_y"], color="#1f77b4", lw=1.2, label="pose graph", zorder=4)
    kept = sum(1 for lp in loops if int(lp["inlier"]))
    ax.plot([], [], color="#2ca02c", label="loop edges kept (%d)" % kept)
    ax.plot([], [], color="#d62728", label="rejected by the loss (%d)" % (len(loops) - kept))
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_title(a.title)
    ax.legend(loc="best", fontsize=8)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(a.out)


if __name__ == "__main__":
    main()
