#!/usr/bin/python3
"""Fits the candidate scorer (config/default.yaml, section scoring) and cross-validates it.

The scorer is a logistic model of the feature vector of a candidate (candidate_scorer.hpp), which
`mild_offline --details` writes as the columns named x_*: this script reads them as they are, so
the features are defined once, in C++. It is fitted by L2-regularised maximum likelihood (Newton's
method) on every candidate of sequences with ground truth, verified or not (the published
probability ranks them all): right pairs are 1, wrong ones 0, don't-care ones left out. Then it is
refitted a few rounds on each query's best candidate under the weights found, because that is the
candidate whose probability is published first and scored.

Every kind of data weighs the same in the fit, whatever its number of sequences and candidates,
except real frames, which weigh three times as much (--kind-weight real=3: real cameras are what
users have; the renders stand in for them), and a wrong candidate weighs twice a right one
(--wrong-weight 2). Both were chosen among 1-6 and 1-3 on the ORB runs: of the choices that keep
precision at the decision >= 0.98 on every public sequence at every step (pub_city >= 0.95), the one
with the lowest ECE on real frames (docs/calibration.md). A kind is a sequence name without a trailing _k<step> (the keyframe step of ../shared/bench/
subsample.py: pub_city_k5 is pub_city at every 5th frame; no suffix is step 1) and without a
trailing _s<seed> (pub_campus_s7 is a pub_campus), and every real-camera sequence (name starting
with gp_, real_ or rtab_) is the kind "real". Inside a kind, each keyframe step weighs the same, and inside
a step each sequence.

A candidate that failed verification is published through the verification gate (its probability
scaled below the decision, candidate_scorer.hpp: belowDecision): the metrics and the choice of each
query's best candidate here apply it too.

Usage:
  fit_scoring.py RUN [RUN ...] [--l2 0.001] [--wrong-weight 2] [--kind-weight real=3] [--decision P] [--cv] [--cv-steps] [--json OUT.json]
RUN is NAME=SEQUENCE_DIR:DETAILS.csv (SEQUENCE_DIR holds gt_loops.txt). With --cv each kind is left
out in turn, the scorer fitted on the others and scored on the runs of the kind left out
(recall@100%P, AP, and precision/recall at the decision, --decision); with --cv-steps each keyframe step
likewise. Prints the fit on all runs as a YAML section.
"""
import json
import math
import os
import re
import sys

import numpy as np


def step_of(name):
    m = re.search(r"_k(\d+)$", name)
    return int(m.group(1)) if m else 1


def kind_of(name):
    name = re.sub(r"_k\d+$", "", name)
    if name.startswith(("gp_", "real_", "rtab_")):
        return "real"
    return re.sub(r"_s\d+$", "", name)


KIND_WEIGHTS = {"real": 3.0}  # --kind-weight KIND=W: a kind's weight in the fit, 1 unless given here
WRONG_WEIGHT = 2.0  # --wrong-weight: a wrong candidate counts this many times a right one in the fit
def default_decision():
    """scoring/decision_probability of config/default.yaml (generated from the C++ declaration): the
    one place the decision is written down."""
    here = os.path.dirname(os.path.abspath(__file__))
    for line in open(os.path.join(here, "..", "config", "default.yaml")):
        m = re.match(r"\s+decision_probability:\s*([\d.]+)", line)
        if m:
            return float(m.group(1))
    sys.exit("config/default.yaml has no scoring/decision_probability: pass --decision")


DECISION = default_decision()  # --decision: where the verification gate caps the unverified
L2 = 0.001


def published(score, verified):
    """The probability mild_lcd publishes (candidate_scorer.cpp): the model's, and for a candidate that
    failed verification at most just below the decision (belowDecision)."""
    p = 1.0 / (1.0 + math.exp(-score))
    return p if verified else min(p, math.nextafter(DECISION, 0.0))


def load_gt(seq):
    truth, dont_care, queries = set(), set(), set()
    with open(f"{seq}/gt_loops.txt") as f:
        for line in f:
            p = line.split()
            if len(p) < 4 or p[0].startswith("#"):
                continue
            pair = (int(p[0]), int(p[1]))
            if p[3] == "1":
                truth.add(pair)
                queries.add(pair[0])
            else:
                dont_care.add(pair)
    return truth, dont_care, queries


def load_run(spec, min_gap=40):
    name, rest = spec.split("=", 1)
    seq, details = rest.rsplit(":", 1)
    truth, dont_care, queries = load_gt(seq)
    rows = []
    with open(details) as f:
        header = f.readline().strip().split(",")
        columns = [c for c in header if c.startswith("x_")]
        if not columns:
            sys.exit(f"{details}: no x_* feature columns (written by mild_offline --details)")
        for line in f:
            row = dict(zip(header, line.strip().split(",")))
            if row.get("fit_skipped") == "1":
                sys.exit(f"{details}: candidates without a fitted model (verification/early_stop): "
                         "write the details with mild_offline --fit-every-candidate")
            i, j = int(row["query"]), int(row["candidate"])
            if i - j < min_gap:
                continue
            label = 1 if (i, j) in truth else (-1 if (i, j) in dont_care else 0)
            rows.append((i, j, [float(row[c]) for c in columns], label, row.get("verified", "1") == "1"))
    return {"name": name, "kind": kind_of(name), "step": step_of(name), "rows": rows, "queries": queries,
            "features": columns}


def row_weights(runs, rows_of):
    """Each descriptor weighs 1, each kind of a descriptor the same, each of its steps 1 / (steps of the kind), each run of a step
    1 / (runs of the step), each row of a run equally."""
    steps_of_kind, runs_of_step = {}, {}
    kinds_of_descriptor = {}
    for r in runs:
        kind = (r.get("descriptor", ""), r["kind"])
        kinds_of_descriptor.setdefault(kind[0], set()).add(kind)
        steps_of_kind.setdefault(kind, set()).add(r["step"])
        runs_of_step[(kind, r["step"])] = runs_of_step.get((kind, r["step"]), 0) + 1
    x, y, w = [], [], []
    for r in runs:
        kind = (r.get("descriptor", ""), r["kind"])
        labelled = [row for row in rows_of(r) if row[3] >= 0]
        share = len(kinds_of_descriptor[kind[0]]) * len(steps_of_kind[kind]) * runs_of_step[(kind, r["step"])]
        share /= KIND_WEIGHTS.get(r["kind"], 1.0)
        for _, _, f, lab, _ in labelled:
            x.append(f)
            y.append(lab)
            w.append((1.0 if lab == 1 else WRONG_WEIGHT) / (len(labelled) * share))
    return np.array(x, dtype=float), np.array(y, dtype=float), np.array(w, dtype=float)


def best_scored(run, weights, bias):
    """Each query's best candidate under the weights, as {query: (published probability, row)}: the
    one the evaluation (and a user acting on the best candidate) sees."""
    best = {}
    for row in run["rows"]:
        s = published(bias + float(np.dot(weights, row[2])), row[4])
        if row[0] not in best or s > best[row[0]][0]:
            best[row[0]] = (s, row)
    return best


def best_rows(run, weights, bias):
    return [row for _, row in best_scored(run, weights, bias).values()]


def fit(runs, l2, rounds=3):
    weights, bias = fit_rows(*row_weights(runs, lambda r: r["rows"]), l2)
    for _ in range(rounds):
        weights, bias = fit_rows(*row_weights(runs, lambda r: best_rows(r, weights, bias)), l2)
    return weights, bias


def fit_rows(x, y, w, l2):
    w = w / w.sum()
    x = np.hstack([x, np.ones((len(x), 1))])
    beta = np.zeros(x.shape[1])
    penalty = l2 * np.eye(x.shape[1])
    penalty[-1, -1] = 0.0  # the bias is not shrunk
    for _ in range(100):
        p = 1.0 / (1.0 + np.exp(-(x @ beta)))
        gradient = x.T @ (w * (p - y)) + penalty @ beta
        hessian = (x * (w * p * (1 - p))[:, None]).T @ x + penalty + 1e-12 * np.eye(x.shape[1])
        step = np.linalg.solve(hessian, gradient)
        beta -= step
        if np.max(np.abs(step)) < 1e-10:
            break
    return beta[:-1], beta[-1]


def metrics(run, weights, bias):
    ranked = sorted(((s, row[3]) for s, row in best_scored(run, weights, bias).values()), key=lambda v: -v[0])
    n = max(1, len(run["queries"]))
    tp = fp = 0
    r100 = ap = prev = 0.0
    k = 0
    while k < len(ranked):
        s = ranked[k][0]
        while k < len(ranked) and ranked[k][0] == s:
            tp += ranked[k][1] == 1
            fp += ranked[k][1] == 0
            k += 1
        recall, precision = tp / n, tp / max(1, tp + fp)
        if fp == 0:
            r100 = recall
        ap += precision * (recall - prev)
        prev = recall
    right = sum(1 for s, lab in ranked if s >= DECISION and lab == 1)
    wrong = sum(1 for s, lab in ranked if s >= DECISION and lab == 0)
    return {"recall_at_100_precision": r100, "average_precision": ap,
            "precision_at_decision": right / max(1, right + wrong) if right + wrong else 1.0,
            "recall_at_decision": right / n, "wrong_at_decision": wrong}


REFEREE_BINS = (0, 0.1, 0.3, 0.5, 0.7, 0.9, 1.0)  # ../shared/bench/calibration.py's default bins


def ece_of(scored, edges=REFEREE_BINS):
    """The bench referee's expected calibration error (../shared/bench/calibration.py) of
    (probability, is_true) pairs, one per query's best candidate."""
    total, err = len(scored), 0.0
    for k, (lo, hi) in enumerate(zip(edges, edges[1:])):
        last = k == len(edges) - 2
        cell = [(s, t) for s, t in scored if lo <= s < hi or (last and s == hi)]
        if cell:
            err += len(cell) * abs(sum(s for s, _ in cell) / len(cell) - sum(t for _, t in cell) / len(cell))
    return err / max(1, total)


def ece(run, weights, bias):
    """ece_of each query's best candidate under the weights, don't-care pairs skipped."""
    return ece_of([(s, row[3] == 1) for s, row in best_scored(run, weights, bias).values() if row[3] >= 0])


def main():
    args = sys.argv[1:]
    l2 = 0.001
    if "--l2" in args:
        l2 = float(args[args.index("--l2") + 1])
        args.remove(args[args.index("--l2") + 1])
        args.remove("--l2")
    global WRONG_WEIGHT
    if "--wrong-weight" in args:
        WRONG_WEIGHT = float(args[args.index("--wrong-weight") + 1])
        args.remove(args[args.index("--wrong-weight") + 1])
        args.remove("--wrong-weight")
    while "--kind-weight" in args:
        at = args.index("--kind-weight")
        kind, weight = args[at + 1].split("=")
        KIND_WEIGHTS[kind] = float(weight)
        del args[at:at + 2]
    global DECISION
    if "--decision" in args:
        DECISION = float(args[args.index("--decision") + 1])
        args.remove(args[args.index("--decision") + 1])
        args.remove("--decision")
    json_out = None
    if "--json" in args:
        json_out = args[args.index("--json") + 1]
        args.remove(json_out)
        args.remove("--json")
    cv = "--cv" in args
    cv_steps = "--cv-steps" in args
    specs = [a for a in args if not a.startswith("--")]
    if not specs:
        sys.exit(__doc__)
    runs = [load_run(s) for s in specs]
    if len({tuple(r["features"]) for r in runs}) != 1:
        sys.exit("the details files have different feature columns: re-run mild_offline on every sequence")
    report = {"features": runs[0]["features"], "cv": []}
    if cv:
        print("| left out | run | recall@100%P | AP | precision at the decision | recall at the decision |")
        print("|---|---|---|---|---|---|")
        for kind in sorted({r["kind"] for r in runs}):
            w, b = fit([r for r in runs if r["kind"] != kind], l2)
            for r in (r for r in runs if r["kind"] == kind):
                m = metrics(r, w, b)
                report["cv"].append({"kind": kind, "run": r["name"], **m})
                print(f"| {kind} | {r['name']} | {m['recall_at_100_precision']:.3f} | {m['average_precision']:.3f} | "
                      f"{m['precision_at_decision']:.3f} ({m['wrong_at_decision']} wrong) | {m['recall_at_decision']:.3f} |")
    if cv_steps:
        print("| left out step | run | recall@100%P | AP | precision at the decision | recall at the decision |")
        print("|---|---|---|---|---|---|")
        report["cv_steps"] = []
        for step in sorted({r["step"] for r in runs}):
            w, b = fit([r for r in runs if r["step"] != step], l2)
            for r in (r for r in runs if r["step"] == step):
                m = metrics(r, w, b)
                report["cv_steps"].append({"step": step, "run": r["name"], **m})
                print(f"| {step} | {r['name']} | {m['recall_at_100_precision']:.3f} | {m['average_precision']:.3f} | "
                      f"{m['precision_at_decision']:.3f} ({m['wrong_at_decision']} wrong) | {m['recall_at_decision']:.3f} |")
    w, b = fit(runs, l2)
    report["weights"] = [round(float(v), 3) for v in w]
    report["bias"] = round(float(b), 3)
    print("scoring:")
    print(f"  # fitted by scripts/fit_scoring.py on {', '.join(r['name'] for r in runs)} (l2 {l2})")
    print(f"  # features: {', '.join(runs[0]['features'])}")
    print(f"  weights: [{', '.join(f'{v:.3f}' for v in w)}]")
    print(f"  bias: {b:.3f}")
    if json_out:
        with open(json_out, "w") as f:
            json.dump(report, f, indent=1)


if __name__ == "__main__":
    main()
