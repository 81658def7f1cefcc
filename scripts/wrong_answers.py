#!/usr/bin/python3
"""What the detector's wrong answers are: each query's best candidate that the ground truth calls
wrong, at the configuration's decision (scoring/decision_probability: the answers a back-end that
acts on LoopCandidate.accepted takes) and among the highest-ranked ones (those that end recall@100%P), sorted into kinds measured from the bench's own files.

Rendered sequences (poses.txt, visible_points.txt), by the first rule that holds:
  - "query sees no wall": the query or the candidate sees no wall sample point within 25 m
    (visible_points.txt is 0), so the ground truth lists no pair for it, whatever the image shows
    (far buildings, open views);
  - "near miss": the cameras are within 10 m and 60 degrees (the same place, beyond the rule's
    5 m / 45 degrees / overlap 0.5);
  - "own recent past": the candidate is at most 300 frames older (30 s at 10 Hz) and within 60 m on
    a heading within 45 degrees: the street just walked, seen again from further on;
  - "another place": anything else (another place of the same material or texture).
Real sequences (frame-aligned traverses, real/README.md; no poses), by the route positions k and j
of query and candidate:
  - "own traverse": both frames on the same walk;
  - "near miss": |k - j| <= 10 route frames (the rule's true pairs are |k - j| <= 2);
  - "another place": anything else.

Usage: wrong_answers.py RUN [RUN ...] [--top N] [--json OUT] [--config CONFIG.yaml]
RUN is NAME=SEQUENCE_DIR:CANDIDATES.csv (mild_offline --output). --top N also classifies the N
highest-ranked wrong answers of each run (default 10). --config is the detector configuration the
runs used, whose scoring/decision_probability is the decision (default config/default.yaml).
"""
import json
import math
import os
import sys
from collections import Counter

import yaml

DEFAULT_CONFIG = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "config", "default.yaml")


def decision_probability(config_path):
    """scoring/decision_probability of a detector configuration; config/default.yaml's when the file
    does not set it (a configuration lists only what it changes)."""
    with open(DEFAULT_CONFIG) as f:
        value = yaml.safe_load(f)["scoring"]["decision_probability"]
    if config_path:
        with open(config_path) as f:
            value = ((yaml.safe_load(f) or {}).get("scoring") or {}).get("decision_probability", value)
    return float(value)


def load_gt(seq):
    truth, dont_care = set(), set()
    with open(f"{seq}/gt_loops.txt") as f:
        for line in f:
            p = line.split()
            if len(p) < 4 or p[0].startswith("#"):
                continue
            (truth if p[3] == "1" else dont_care).add((int(p[0]), int(p[1])))
    return truth, dont_care


def best_candidates(csv_path, min_gap=40):
    best = {}
    with open(csv_path) as f:
        f.readline()
        for line in f:
            i, j, s = line.strip().split(",")
            i, j, s = int(i), int(j), float(s)
            if i - j >= min_gap and (i not in best or s > best[i][1]):
                best[i] = (j, s)
    return best


def read_columns(path):
    try:
        with open(path) as f:
            return [[float(x) for x in line.split()] for line in f if line.strip() and not line.startswith("#")]
    except OSError:
        return None


def classifier(seq):
    poses = read_columns(f"{seq}/poses.txt")
    visible = read_columns(f"{seq}/visible_points.txt")
    if poses is None:  # real: frame-aligned traverses
        info = json.load(open(f"{seq}/info.json"))
        second = info["frames"]["second"][0]

        def real(i, j):
            if (i >= second) == (j >= second):
                return "own traverse"
            k = i - second if i >= second else i
            return "near miss" if abs(k - j) <= 10 else "another place"
        return real

    def rendered(i, j):
        if visible is not None and (visible[i][-1] == 0 or visible[j][-1] == 0):
            return "query sees no wall"
        dx, dy = poses[i][0] - poses[j][0], poses[i][1] - poses[j][1]
        distance = math.hypot(dx, dy)
        heading = abs((poses[i][2] - poses[j][2] + math.pi) % (2 * math.pi) - math.pi) * 180 / math.pi
        if distance <= 10 and heading <= 60:
            return "near miss"
        if i - j <= 300 and distance <= 60 and heading <= 45:
            return "own recent past"
        return "another place"
    return rendered


def main():
    args = sys.argv[1:]
    top, json_out, config = 10, None, None
    if "--top" in args:
        top = int(args[args.index("--top") + 1])
        del args[args.index("--top"):args.index("--top") + 2]
    if "--json" in args:
        json_out = args[args.index("--json") + 1]
        del args[args.index("--json"):args.index("--json") + 2]
    if "--config" in args:
        config = args[args.index("--config") + 1]
        del args[args.index("--config"):args.index("--config") + 2]
    if not args:
        sys.exit(__doc__)
    decision = decision_probability(config)
    print(f"decision: probability >= {decision:g} (scoring/decision_probability of {config or 'config/default.yaml'})\n")
    report = {}
    totals = {"at_decision": Counter(), "top": Counter()}
    print(f"| sequence | wrong at p >= {decision:g} | of which | highest-ranked wrong answers | of which |")
    print("|---|---|---|---|---|")
    for spec in args:
        name, rest = spec.split("=", 1)
        seq, csv_path = rest.rsplit(":", 1)
        truth, dont_care = load_gt(seq)
        kind_of = classifier(seq)
        wrong = sorted(((s, i, j) for i, (j, s) in best_candidates(csv_path).items()
                        if (i, j) not in truth and (i, j) not in dont_care), reverse=True)
        at_decision = Counter(kind_of(i, j) for s, i, j in wrong if s >= decision)
        highest = Counter(kind_of(i, j) for s, i, j in wrong[:top])
        totals["at_decision"].update(at_decision)
        totals["top"].update(highest)
        report[name] = {"at_decision": dict(at_decision), "top": dict(highest)}
        fmt = lambda c: ", ".join(f"{k} {v}" for k, v in c.most_common()) or "-"
        print(f"| {name} | {sum(at_decision.values())} | {fmt(at_decision)} | {min(top, len(wrong))} | {fmt(highest)} |")
    for key, label in (("at_decision", f"wrong at p >= {decision:g}"), ("top", f"the {top} highest-ranked per sequence")):
        c = totals[key]
        n = sum(c.values())
        if n:
            print(f"\nAll sequences, {label} ({n}): " +
                  ", ".join(f"{k} {v} ({100 * v / n:.0f} %)" for k, v in c.most_common()))
    if json_out:
        with open(json_out, "w") as f:
            json.dump({"decision_probability": decision, "runs": report,
                       "totals": {k: dict(v) for k, v in totals.items()}}, f, indent=1)


if __name__ == "__main__":
    main()
