#!/usr/bin/python3
"""Plot for mild_analysis --plot: accuracy R against complexity E for each probe radius r, one
point per number of tables m (as the seed paper's "Complexity and Accuracy under different MIH
parameters" figure).

Usage: plot_analysis.py ANALYSIS.json OUTPUT.png   (ANALYSIS.json is written by mild_analysis --plot)
"""
import json
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402


def main():
    data = json.load(open(sys.argv[1]))
    rows = data["rows"]
    fig, ax = plt.subplots(figsize=(6, 4.2), dpi=120)
    for r in sorted({row["r"] for row in rows}):
        line = sorted((row for row in rows if row["r"] == r), key=lambda row: row["m"])
        ax.plot([row["E"] for row in line], [row["R"] for row in line], "o-", ms=3, lw=1.2, label=f"r = {r}")
        for row in (row for row in line if row["m"] % 4 == 0 and row["R"] < 0.97):
            ax.annotate(str(row["m"]), (row["E"], row["R"]), fontsize=6, xytext=(3, -8), textcoords="offset points")
    ax.axhline(data.get("min_accuracy", 0.8), color="grey", lw=0.8, ls="--")
    ax.set_xscale("log")
    ax.set_xlabel("complexity E (fraction of outliers visited)")
    ax.set_ylabel("accuracy R (fraction of inliers found)")
    ax.set_title(f"MIH, {data['model']} model (numbers: m)", fontsize=9)
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(sys.argv[2])


if __name__ == "__main__":
    main()
