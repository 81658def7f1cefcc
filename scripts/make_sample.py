#!/usr/bin/python3
"""Cuts a contiguous or strided excerpt of a ../shared/bench sequence into the bench layout.

Usage: make_sample.py SEQUENCE_DIR OUT_DIR FIRST LAST [STRIDE]
Copies frames FIRST..LAST (inclusive) every STRIDE frames, renumbered from 0, with times.txt,
poses.txt and gt_loops.txt restricted and re-indexed to the kept frames (pairs whose frames are
both kept; the EVALUATION.md gap of 40 frames is not re-checked, so a strided excerpt keeps the
original pairs). Used once to make sample/ and test/data/; kept for provenance.
"""
import os
import shutil
import sys


def main():
    if len(sys.argv) not in (5, 6):
        sys.exit(__doc__)
    src, out, first, last = sys.argv[1], sys.argv[2], int(sys.argv[3]), int(sys.argv[4])
    stride = int(sys.argv[5]) if len(sys.argv) == 6 else 1
    frames = sorted(os.listdir(os.path.join(src, "images")))
    kept = list(range(first, last + 1, stride))
    new_index = {old: new for new, old in enumerate(kept)}
    os.makedirs(os.path.join(out, "images"), exist_ok=True)
    for old, new in new_index.items():
        ext = os.path.splitext(frames[old])[1]
        shutil.copyfile(os.path.join(src, "images", frames[old]), os.path.join(out, "images", f"{new:06d}{ext}"))
    for name in ("times.txt", "poses.txt"):
        with open(os.path.join(src, name)) as f:
            lines = f.readlines()
        with open(os.path.join(out, name), "w") as f:
            f.writelines(lines[old] for old in kept)
    with open(os.path.join(src, "gt_loops.txt")) as f, open(os.path.join(out, "gt_loops.txt"), "w") as g:
        for line in f:
            parts = line.split()
            if len(parts) < 4:
                continue
            i, j = int(parts[0]), int(parts[1])
            if i in new_index and j in new_index:
                g.write(f"{new_index[i]} {new_index[j]} {parts[2]} {parts[3]}\n")


if __name__ == "__main__":
    main()
