#!/usr/bin/env python3
"""What each stage costs and what it buys: one row per configuration, mild_offline on every sequence.

Each row changes one thing from the defaults (config/default.yaml) and runs mild_offline with
--stats and --gt on the same sequences, one after another on one thread. Columns: ms per keyframe
per stage (the median over all keyframes of all sequences) and recall@100%P / AP, the mean over the
real sequences and over the rendered ones. Times are also given as a ratio to the first row, run
again last, so that the noise of the machine shows (two default rows that differ by x% mean the
other ratios are good to about x%). Prints a Markdown table; the raw figures go to OUT/cost.json.

Usage (scripts/bench_cost.sh builds mild_offline and passes these):
  cost_accuracy.py --offline BIN/mild_offline --out DIR --sequence name=folder ... [--rows a,b]
"""
import argparse
import json
import os
import re
import statistics
import subprocess
import sys

# One row per configuration: name -> the YAML that differs from the defaults. The first row is the
# baseline every ratio refers to.
ROWS = {
    "default": "",
    "orb/num_features 400": "orb:\n  num_features: 400\n",
    "orb/num_features 1200": "orb:\n  num_features: 1200\n",
    "orb/fast_threshold 20": "orb:\n  fast_threshold: 20\n",
    "detector/max_candidates 1": "detector:\n  max_candidates: 1\n",
    "detector/max_candidates 2": "detector:\n  max_candidates: 2\n",
    "verification/method usac": "verification:\n  method: usac\n",
    "verification/method usac_fast": "verification:\n  method: usac_fast\n",
    "verification/method usac_prosac": "verification:\n  method: usac_prosac\n",
    "verification/method ransac": "verification:\n  method: ransac\n",
    "index/max_candidates_per_feature 256": "index:\n  max_candidates_per_feature: 256\n",
    "index/max_candidates_per_feature 1024": "index:\n  max_candidates_per_feature: 1024\n",
    "verification/early_stop false": "verification:\n  early_stop: false\n",
    "verification/enabled false": "verification:\n  enabled: false\n",
    # The cost-accuracy frontier of docs/accuracy.md: descriptors and budgets (ROWS=frontier).
    "orb/num_features 1500": "orb:\n  num_features: 1500\n",
    "orb/num_features 3000": "orb:\n  num_features: 3000\n",
    "features/type brisk": "features:\n  type: brisk\n",
    "features/type akaze": "features:\n  type: akaze\n",
    "akaze, octaves 2": "features:\n  type: akaze\nakaze:\n  octaves: 2\n",
    # features/max_pixels: frames larger than the cap shrunk before extraction (640 x 360 to 320 x 180 and
    # 369 x 207; the renders' 320 x 240 only by the smaller cap, to 277 x 207).
    "akaze max_pixels 57600": "features:\n  type: akaze\n  max_pixels: 57600\n",
    "akaze max_pixels 76800": "features:\n  type: akaze\n  max_pixels: 76800\n",
    # One sub-level per octave makes the capped scale space cheap enough; a lower threshold gives back the
    # features that costs (config/real_cameras_budget.yaml).
    "akaze max_pixels 76800 octave_layers 1":
        "features:\n  type: akaze\n  max_pixels: 76800\nakaze:\n  octave_layers: 1\n",
    "akaze max_pixels 76800 octave_layers 1 threshold 0.00005":
        "features:\n  type: akaze\n  max_pixels: 76800\nakaze:\n  octave_layers: 1\n  threshold: 0.00005\n",
}
FRONTIER = ["default", "orb/num_features 1500", "orb/num_features 3000", "features/type brisk", "features/type akaze",
            "akaze, octaves 2", "akaze max_pixels 57600", "akaze max_pixels 76800",
            "akaze max_pixels 76800 octave_layers 1", "akaze max_pixels 76800 octave_layers 1 threshold 0.00005"]
STAGES = ["extract_ms", "query_ms", "filter_ms", "verify_ms", "keyframe_ms", "keyframe_cpu_ms"]


def run(offline, out, row, yaml_text, name, folder):
    tag = re.sub(r"[^A-Za-z0-9]+", "_", row).strip("_")
    work = os.path.join(out, tag)
    os.makedirs(work, exist_ok=True)
    config = os.path.join(work, "config.yaml")
    with open(config, "w") as f:
        f.write(yaml_text)
    stats = os.path.join(work, name + "_stats.json")
    cmd = [offline, "--images", folder, "--output", os.path.join(work, name + ".csv"), "--gt",
           os.path.join(folder, "gt_loops.txt"), "--min-gap", "40", "--stats", stats]
    if yaml_text:
        cmd += ["--config", config]
    text = subprocess.run(cmd, check=True, capture_output=True, text=True).stdout
    recall = float(re.search(r"recall@100%P: ([0-9.]+)", text).group(1))
    ap = float(re.search(r"average precision: ([0-9.]+)", text).group(1))
    return recall, ap, stats


def median_times(stats_json, statistic="median"):
    """Each stage's median (or mean) ms per keyframe, and the number of keyframes, from mild_offline --stats."""
    with open(stats_json) as f:
        s = json.load(f)
    return {k: s[k][statistic] if k in s else 0.0 for k in STAGES}, s.get("keyframes", 0)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--offline", required=True)
    ap.add_argument("--out", required=True)
    ap.add_argument("--sequence", action="append", required=True, help="name=folder; names gp_* are real")
    ap.add_argument("--rows", default="", help="comma-separated row names, or frontier (default: every row)")
    args = ap.parse_args()
    rows = FRONTIER if args.rows == "frontier" else [r for r in args.rows.split(",") if r] if args.rows else list(ROWS)
    for r in rows:
        if r not in ROWS:
            sys.exit(f"unknown row {r!r}; rows: {', '.join(ROWS)}")
    order = rows + [rows[0] + " (again)"]  # the baseline once more, last: the run's noise
    sequences = [s.split("=", 1) for s in args.sequence]
    results = {}
    for row in order:
        base = row.replace(" (again)", "")
        per_seq = {}
        for name, folder in sequences:
            recall, avg_p, stats = run(args.offline, args.out, row, ROWS[base], name, folder)
            times, keyframes = median_times(stats)
            per_seq[name] = {"recall_at_100p": recall, "ap": avg_p, "median_ms": times, "keyframes": keyframes,
                             "mean_ms": median_times(stats, "mean")[0]}
            print(f"[cost] {row:40s} {name:14s} r100 {recall:.3f} AP {avg_p:.3f} "
                  f"keyframe {times['keyframe_ms']:.1f} ms", file=sys.stderr, flush=True)
        results[row] = per_seq
    os.makedirs(args.out, exist_ok=True)
    with open(os.path.join(args.out, "cost.json"), "w") as f:
        json.dump(results, f, indent=1)

    def mean(row, real, key):
        vals = [v[key] for n, v in results[row].items() if n.startswith("gp_") == real]
        return statistics.mean(vals) if vals else float("nan")

    def stage(row, key):
        # Keyframe-weighted mean of the sequences' medians: one figure per stage for the row.
        seqs = results[row].values()
        total = sum(v["keyframes"] for v in seqs)
        return sum(v["median_ms"][key] * v["keyframes"] for v in seqs) / max(1, total)

    base = order[0]
    print("| configuration | extract | query | filter | verify | keyframe | keyframe CPU (x default) "
          "| real r100 / AP | rendered r100 / AP |")
    print("|---|---|---|---|---|---|---|---|---|")
    for row in order:
        ratio = stage(row, "keyframe_cpu_ms") / max(1e-9, stage(base, "keyframe_cpu_ms"))
        print(f"| {row} | {stage(row, 'extract_ms'):.1f} | {stage(row, 'query_ms'):.1f} | {stage(row, 'filter_ms'):.2f} | "
              f"{stage(row, 'verify_ms'):.1f} | {stage(row, 'keyframe_ms'):.1f} | "
              f"{stage(row, 'keyframe_cpu_ms'):.1f} ({ratio:.2f}) | "
              f"{mean(row, True, 'recall_at_100p'):.3f} / {mean(row, True, 'ap'):.3f} | "
              f"{mean(row, False, 'recall_at_100p'):.3f} / {mean(row, False, 'ap'):.3f} |")
    names = [n for n, _ in sequences]
    def real_mean(row, key):
        # The mean whole keyframe over every real keyframe (a user's budget is the mean, not the median).
        real = [v for n, v in results[row].items() if n.startswith("gp_")]
        total = sum(v["keyframes"] for v in real)
        return sum(v["mean_ms"][key] * v["keyframes"] for v in real) / max(1, total)

    print("\n| configuration | keyframe ms at 640 x 360 (real, wall, median) | mean keyframe, wall (x default) "
          "| mean keyframe, CPU (x default) | " + " | ".join(names) + " |")
    print("|---|---|---|---|" + "---|" * len(names))
    for row in order:
        real = [v for n, v in results[row].items() if n.startswith("gp_")]
        total = sum(v["keyframes"] for v in real)
        real_ms = sum(v["median_ms"]["keyframe_ms"] * v["keyframes"] for v in real) / max(1, total)
        wall, cpu = real_mean(row, "keyframe_ms"), real_mean(row, "keyframe_cpu_ms")
        print(f"| {row} | {real_ms:.1f} | {wall:.1f} ({wall / max(1e-9, real_mean(base, 'keyframe_ms')):.2f}) | "
              f"{cpu:.1f} ({cpu / max(1e-9, real_mean(base, 'keyframe_cpu_ms')):.2f}) | " + " | ".join(
            f"{results[row][n]['recall_at_100p']:.3f} / {results[row][n]['ap']:.3f}" for n in names) + " |")
    print("\nms: median per keyframe of each sequence, weighted by its keyframes; stages and keyframe in wall time, "
          "keyframe CPU in the thread's CPU time (robust to other processes); accuracy: mean over the sequences of "
          "each kind (real = gp_*).")


if __name__ == "__main__":
    main()
