#!/usr/bin/python3
"""Calibration of the published loop probability, per run and with each kind of data left out.

Usage (scripts/bench_calibration.sh passes these):
  calibration_report.py --bench BENCH --results DIR [--plots DIR] [--fit] [--decision P] DESC/NAME=SEQUENCE_DIR ...

DIR/DESC/NAME.csv are mild_offline's candidates with the default scorer, DIR/DESC/NAME.details.csv
every candidate with its scorer features (x_* columns, candidate_scorer.cpp) and --fit-every-candidate.
Prints Markdown tables:
  1. each run as published: the ECE by the bench's referee (BENCH/calibration.py), recall@100%P / AP
     (BENCH/score.py), and precision / recall of each query's best candidate at the decision
     probability (scoring/decision_probability, `accepted`);
  2. the scorer refitted (scripts/fit_scoring.py, the default's recipe) without each kind in turn
     -- real frames, each render kind, each keyframe step (fitted on ORB runs, as the default) and
     each descriptor (fitted on the others) -- and scored on what was left out: ECE (the referee's
     bins), recall@100%P, AP;
  3. one table per kind of data (real day, real night, real corridors, each render kind) for the
     descriptor the default was fitted on: 1 and 2 side by side, every keyframe step;
  4. the runs of generated scenes whose seed is in --held-out-seeds (other rooms, routes and textures of
     every kind, rendered by ../shared/bench/generator): never fitted on, in none of the fits above,
     scored as published, as in 1, with a summary per descriptor;
and draws a reliability diagram per kind (real day, real night, each render kind, each descriptor, and
the never-fitted scenes per kind) from the published candidates into --plots. With --fit, prints the
scorer fitted on every run but the never-fitted ones.
"""
import argparse
import json
import math
import os
import re
import subprocess
import sys

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
import fit_scoring  # noqa: E402

FIT_DESCRIPTORS = {"orb"}  # the default scorer was fitted on ORB runs only (candidate_scorer.hpp)
ece_of = fit_scoring.ece_of  # the bench referee's binning


def scored_best(score, seq, csv):
    """(probability, is_true) of each query's best candidate in a candidates CSV, by the bench referee's
    rules (score.py: at least 40 frames back, don't-care pairs skipped)."""
    truth, dont_care, _ = fit_scoring.load_gt(seq)
    best = score.load_candidates(csv, 40)
    return [(s, (i, j) in truth) for i, (j, s) in best.items() if (i, j) not in dont_care]


def at_decision(scored, n_queries, decision):
    right = sum(1 for s, t in scored if s >= decision and t)
    wrong = sum(1 for s, t in scored if s >= decision and not t)
    return {"precision_at_decision": right / (right + wrong) if right + wrong else float("nan"),
            "recall_at_decision": right / max(1, n_queries), "wrong_at_decision": wrong}


def score_json(bench, seq, csv):
    out = subprocess.run(["/usr/bin/python3", f"{bench}/score.py", seq, csv, "--json"], capture_output=True,
                         text=True, check=True)
    return json.loads(out.stdout)


def kind_name(name):
    base = re.sub(r"_k\d+$", "", name)
    if base.startswith("rtab_"):
        return "real corridors"
    if base.startswith("gp_") or base.startswith("real_"):
        return "real night" if "night" in base else "real day"
    return re.sub(r"_s\d+$", "", base)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--bench", required=True)
    ap.add_argument("--results", required=True)
    ap.add_argument("--plots")
    ap.add_argument("--fit", action="store_true")
    ap.add_argument("--decision", type=float, default=None,
                    help="the decision probability (default: config/default.yaml's)")
    ap.add_argument("--held-out-seeds", default="",
                    help="comma-separated generator seeds whose runs are never fitted on and are printed apart")
    ap.add_argument("runs", nargs="+")
    a = ap.parse_args()
    held_seeds = {x for x in a.held_out_seeds.split(",") if x}
    decision = a.decision if a.decision is not None else fit_scoring.default_decision()
    fit_scoring.DECISION = decision
    runs = []
    for spec in a.runs:
        rid, seq = spec.split("=", 1)
        desc, name = rid.split("/", 1)
        run = fit_scoring.load_run(f"{name}={seq}:{a.results}/{rid}.details.csv")
        seed = re.search(r"_s(\d+)(?:_k\d+)?$", name)
        run.update({"id": rid, "descriptor": desc, "seq": seq, "csv": f"{a.results}/{rid}.csv",
                    "label": kind_name(name), "held_out": bool(seed) and seed.group(1) in held_seeds})
        runs.append(run)
    held = [r for r in runs if r["held_out"]]
    runs = [r for r in runs if not r["held_out"]]

    # 1. As published, by the bench's own referees.
    sys.path.insert(0, a.bench)
    import calibration  # noqa: E402
    import score  # noqa: E402
    print(f"\nAs published (decision probability {decision}): ECE by ../shared/bench/calibration.py, "
          "recall@100%P / AP by score.py, each query's best candidate at the decision.\n")
    published = published_table(runs, a.bench, calibration, score, decision)

    # 2. Left out.
    groupings = [("kind", lambda r: r["kind"]), ("descriptor", lambda r: r["descriptor"]),
                 ("step", lambda r: r["step"])]
    print("\nThe scorer refitted without each kind, descriptor and step in turn (scripts/fit_scoring.py), "
          "scored on what was left out: ECE (the referee's bins) / recall@100%P / AP.\n")
    heads = [g for g, key in groupings if len({key(r) for r in runs}) > 1]
    print("| descriptor | sequence | step | " + " | ".join(f"{h} left out" for h in heads) + " |")
    print("|---|---|---|" + "---|" * len(heads))
    left = {r["id"]: {} for r in runs}
    for g, key in groupings:
        if g not in heads:
            continue
        for value in sorted({key(r) for r in runs}, key=str):
            # The default's recipe (fitted on the FIT_DESCRIPTORS' runs) without what is left out; a
            # descriptor left out is fitted on the others.
            train = [r for r in runs if key(r) != value and (g == "descriptor" or r["descriptor"] in FIT_DESCRIPTORS)]
            if not train:
                continue
            w, b = fit_scoring.fit(train, fit_scoring.L2)
            for r in (r for r in runs if key(r) == value):
                m = fit_scoring.metrics(r, w, b)
                left[r["id"]][g] = (fit_scoring.ece(r, w, b), m["recall_at_100_precision"], m["average_precision"])
    for r in runs:
        cells = [f"{v[0]:.3f} / {v[1]:.3f} / {v[2]:.3f}" if v else "–" for v in (left[r["id"]].get(h) for h in heads)]
        print(f"| {r['descriptor']} | {re.sub(r'_k[0-9]+$', '', r['name'])} | {r['step']} | " + " | ".join(cells) + " |")
    # A grouping with nothing fitted (descriptors without the fitted one, e.g. DESCRIPTORS=brisk,akaze) has no worst.
    worst = {h: max((left[r["id"]][h][0] for r in runs if h in left[r["id"]]), default=None) for h in heads}
    print("\nWorst left-out ECE: " + ", ".join(f"{h} {v:.3f}" if v is not None else f"{h} –" for h, v in worst.items()))

    # 4. One table per kind, the default's descriptor: what docs/accuracy.md shows.
    print("\nOne table per kind (the default's descriptor, as published; kind left out: the scorer refitted "
          "without the kind, ECE on it):")
    for label in dict.fromkeys(r["label"] for r in runs):
        mine = [(r, row) for r, row in zip(runs, published) if r["label"] == label and r["descriptor"] in FIT_DESCRIPTORS]
        if not mine:
            continue
        print(f"\n**{label}**\n")
        print("| sequence | step | ECE | kind left out | recall@100%P / AP | precision at the decision (wrong) | recall at the decision |")
        print("|---|---|---|---|---|---|---|")
        for r, row in mine:
            out = left[r["id"]].get("kind")
            prec = "–" if math.isnan(row["precision_at_decision"]) else f"{row['precision_at_decision']:.3f}"
            print(f"| {re.sub(r'_k[0-9]+$', '', r['name'])} | {r['step']} | {row['ece']:.3f} | "
                  f"{f'{out[0]:.3f}' if out else '–'} | {row['recall_at_100_precision']:.3f} / {row['average_precision']:.3f} | "
                  f"{prec} ({row['wrong_at_decision']}) | {row['recall_at_decision']:.3f} |")

    # 3. Never fitted.
    if held:
        print(f"\nScenes no fit has seen (generator seeds {', '.join(sorted(held_seeds))}), as published:\n")
        rows = published_table(held, a.bench, calibration, score, decision)
        for desc in sorted({r["descriptor"] for r in held}):
            mine = [row for r, row in zip(held, rows) if r["descriptor"] == desc]
            eces = [row["ece"] for row in mine]
            low = [row for row in mine if not math.isnan(row["precision_at_decision"]) and row["precision_at_decision"] < 0.98]
            print(f"\n{desc}, {len(mine)} runs: mean ECE {np.mean(eces):.3f}, worst {max(eces):.3f}, "
                  f"{sum(e <= 0.05 for e in eces)} at most 0.05; mean recall@100%P / AP "
                  f"{np.mean([row['recall_at_100_precision'] for row in mine]):.3f} / "
                  f"{np.mean([row['average_precision'] for row in mine]):.3f}; precision at the decision under 0.98 in "
                  f"{len(low)} runs, {sum(row['wrong_at_decision'] for row in mine)} wrong loops accepted in all")

    if a.plots:
        plot(a.plots, runs + held, score)
    if a.fit:
        w, b = fit_scoring.fit([r for r in runs if r["descriptor"] in FIT_DESCRIPTORS], fit_scoring.L2)
        print(f"\nscoring (fitted on every {', '.join(sorted(FIT_DESCRIPTORS))} run of tables 1 and 2):")
        print(f"  # features: {', '.join(runs[0]['features'])}")
        print(f"  weights: [{', '.join(f'{v:.3f}' for v in w)}]")
        print(f"  bias: {b:.3f}")


def published_table(runs, bench, calibration, score, decision):
    """Prints each run as published (ECE, recall@100%P / AP, precision / recall at the decision) as a
    Markdown table and returns the figures of each."""
    print("| descriptor | sequence | step | scored | ECE | recall@100%P / AP | precision / recall at the decision |")
    print("|---|---|---|---|---|---|---|")
    rows = []
    for r in runs:
        c = calibration.calibration(r["seq"], r["csv"])
        s = score_json(bench, r["seq"], r["csv"])
        m = at_decision(scored_best(score, r["seq"], r["csv"]), len(r["queries"]), decision)
        prec = "–" if math.isnan(m["precision_at_decision"]) else f"{m['precision_at_decision']:.3f}"
        print(f"| {r['descriptor']} | {re.sub(r'_k[0-9]+$', '', r['name'])} | {r['step']} | {c['scored']} | "
              f"{c['ece']:.3f} | {s['recall_at_100_precision']:.3f} / {s['average_precision']:.3f} | {prec} ({m['wrong_at_decision']} wrong) / "
              f"{m['recall_at_decision']:.3f} |")
        rows.append({"ece": c["ece"], **s, **m})
    return rows


def plot(folder, runs, score):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    os.makedirs(folder, exist_ok=True)
    panels = {}
    for r in runs:
        scored = scored_best(score, r["seq"], r["csv"])
        if r.get("held_out"):  # apart: what the probability does on scenes it was not fitted on
            panels.setdefault(("held_out", f"{r['label']}, never fitted"), []).extend(scored)
            continue
        panels.setdefault(("kind", r["label"]), []).extend(scored)
        panels.setdefault(("descriptor", r["descriptor"]), []).extend(scored)
        # Each kind with each descriptor: a row per kind, a column per descriptor.
        panels.setdefault(("kind_and_descriptor", (r["label"], r["descriptor"])), []).extend(scored)
    descriptors = list(dict.fromkeys(r["descriptor"] for r in runs if not r.get("held_out")))
    for group in ("kind", "descriptor", "held_out", "kind_and_descriptor"):
        names = [n for g, n in panels if g == group]
        if not names:
            continue
        cols = min(4, len(names))
        if group == "kind_and_descriptor":  # kind-major, descriptors in the order they were run
            kinds = list(dict.fromkeys(k for k, _ in names))
            names.sort(key=lambda n: (kinds.index(n[0]), descriptors.index(n[1])))
            cols = len(descriptors)
        rows = (len(names) + cols - 1) // cols
        fig, axes = plt.subplots(rows, cols, figsize=(2.8 * cols, 2.9 * rows), dpi=110, squeeze=False)
        for ax in axes.flat[len(names):]:
            ax.axis("off")
        for ax, n in zip(axes.flat, names):
            scored = panels[(group, n)]
            s = np.array([v for v, _ in scored])
            t = np.array([v for _, v in scored], dtype=float)
            edges = np.linspace(0, 1, 11)
            idx = np.minimum((s * 10).astype(int), 9)
            xs, ys, ns = [], [], []
            for k in range(10):
                m = idx == k
                if m.sum():
                    xs.append(s[m].mean())
                    ys.append(t[m].mean())
                    ns.append(int(m.sum()))
            ax.plot([0, 1], [0, 1], ":", color="grey", lw=1)
            ax.bar(edges[:-1] + 0.05, [t[idx == k].mean() if (idx == k).any() else 0 for k in range(10)], width=0.09,
                   color="tab:blue", alpha=0.25)
            ax.plot(xs, ys, "o-", color="tab:blue", ms=3)
            for x, y, c in zip(xs, ys, ns):
                ax.annotate(str(c), (x, y), textcoords="offset points", xytext=(2, -9), fontsize=6)
            title = ", ".join(n) if isinstance(n, tuple) else n
            ax.set_title(f"{title}: {len(scored)} queries\nECE {ece_of(scored):.3f}", fontsize=8)
            ax.set_xlim(0, 1)
            ax.set_ylim(0, 1.02)
            ax.tick_params(labelsize=6)
            ax.set_xlabel("published probability", fontsize=7)
        for row in axes:
            row[0].set_ylabel("fraction true (best candidate)", fontsize=7)
        fig.tight_layout()
        fig.savefig(os.path.join(folder, f"reliability_by_{group}.png"))
        plt.close(fig)


if __name__ == "__main__":
    main()
