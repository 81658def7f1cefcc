#!/usr/bin/python3
"""The keyframe-step table of scripts/bench_steps.sh.

Usage: step_table.py BENCH_DIR OUT_DIR NAME=SEQUENCE_DIR [...]
NAME is <sequence>_k<step>; OUT_DIR holds NAME.csv (mild_offline --output) and NAME.npy
(--similarity). Scores both with the bench's referee (BENCH_DIR/score.py): mild_lcd's published
probabilities, and its similarity top-1 (each query's most similar keyframe at least 40 before it).
Beside them, from BENCH_DIR/PEERS.md (step 1) and PEERS_STEPS.md: the 2017 code's better variant
(the higher of its probability and its similarity, metric by metric) and the best peer (the highest
of every peer, metric by metric, named). Prints a Markdown table and, per row, whether mild_lcd is
at least the 2017 code and at least its own similarity top-1 in AP.
"""
import importlib.util
import os
import re
import sys
import tempfile

import numpy as np

PEERS_STEP1 = ["original MILD (probability)", "original MILD (similarity)", "iBoW-LCD", "DLoopDetector", "HBST"]
PEERS_STEPS = ["original MILD (probability)", "original MILD (similarity)", "iBoW-LCD", "HBST", "DLoopDetector"]


def referee(bench):
    spec = importlib.util.spec_from_file_location("score", os.path.join(bench, "score.py"))
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.score


def pairs(cell):
    return tuple(float(v) for v in cell.split("/")[:2])


def peers(bench):
    """(sequence, step) -> {peer: (recall@100%P, AP)}"""
    table = {}
    for line in open(os.path.join(bench, "PEERS.md")):
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if len(cells) >= 6 and re.match(r"(real/)?(pub_|gp_)", cells[0]) and "/" in cells[1]:
            table[(cells[0].replace("real/", ""), 1)] = dict(zip(PEERS_STEP1, map(pairs, cells[1:6])))
    for line in open(os.path.join(bench, "PEERS_STEPS.md")):
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if len(cells) >= 7 and re.match(r"(pub_|gp_)", cells[0]) and cells[1].isdigit():
            table[(cells[0], int(cells[1]))] = dict(zip(PEERS_STEPS, map(pairs, cells[2:7])))
    return table


def similarity_top1(score, sequence, matrix):
    s = np.load(matrix)
    with tempfile.NamedTemporaryFile("w", suffix=".csv", delete=False) as f:
        f.write("query,candidate,score\n")
        for i in range(40, s.shape[0]):
            row = s[i, : i - 39]
            if row.size and row.max() > 0:
                j = int(row.argmax())
                f.write(f"{i},{j},{row[j]}\n")
    try:
        return score(sequence, f.name, 40)
    finally:
        os.unlink(f.name)


def main():
    if len(sys.argv) < 4:
        sys.exit(__doc__)
    bench, out, specs = sys.argv[1], sys.argv[2], sys.argv[3:]
    score = referee(bench)
    known = peers(bench)
    print("| sequence | step | mild_lcd recall@100%P / AP | mild_lcd similarity top-1 | 2017 code, better variant | "
          "best peer | at least the 2017 code | at least its similarity top-1 (AP) |")
    print("|---|---|---|---|---|---|---|---|")
    below_2017 = below_top1 = 0
    for spec in specs:
        name, sequence = spec.split("=", 1)
        base, step = re.match(r"(.+)_k(\d+)$", name).groups()
        step = int(step)
        ours = score(sequence, os.path.join(out, name + ".csv"), 40)
        r, ap = ours["recall_at_100_precision"], ours["average_precision"]
        top1 = similarity_top1(score, sequence, os.path.join(out, name + ".npy"))
        t_r, t_ap = top1["recall_at_100_precision"], top1["average_precision"]
        ok_top1 = ap >= t_ap
        below_top1 += not ok_top1
        row = known.get((base, step))
        if row:
            mild_r = max(row[PEERS_STEP1[0]][0], row[PEERS_STEP1[1]][0])
            mild_ap = max(row[PEERS_STEP1[0]][1], row[PEERS_STEP1[1]][1])
            best_r = max(row.items(), key=lambda kv: kv[1][0])
            best_ap = max(row.items(), key=lambda kv: kv[1][1])
            ok_2017 = r >= mild_r and ap >= mild_ap
            below_2017 += not ok_2017
            peer = f"{best_r[1][0]:.3f} ({best_r[0]}) / {best_ap[1][1]:.3f} ({best_ap[0]})"
            vs = "yes" if ok_2017 else "**no**"
            mild = f"{mild_r:.3f} / {mild_ap:.3f}"
        else:
            peer = mild = vs = "–"
        print(f"| {base} | {step} | {r:.3f} / {ap:.3f} | {t_r:.3f} / {t_ap:.3f} | {mild} | {peer} | {vs} | "
              f"{'yes' if ok_top1 else '**no**'} |")
    print(f"\nrows below the 2017 code: {below_2017}; rows below mild_lcd's own similarity top-1 in AP: {below_top1}")


if __name__ == "__main__":
    main()
