#!/usr/bin/python3
"""Chooses among candidate configurations by cross-validation that leaves whole kinds of data out,
real camera frames included, and reports each choice's left-out figures.

Each candidate configuration has been run by scripts/bench_accuracy.sh (CONFIG=..., OUT=...) on the
same sequences; this reads their candidates and --details files. For each kind K in turn (a
rendered kind with its generated seeds, or "real"): every configuration's scorer is fitted on the
other kinds (fit_scoring.py's fit), each configuration is judged on the other kinds by the mean over
kinds of (recall@100%P + AP) / 2, the best is chosen, and the chosen one is scored on K with a
scorer that never saw K. The last table is the choice on all kinds: the shipped default.

Usage: cv_choices.py BENCH_DIR CACHE_DIR NAME=OUT_DIR [NAME=OUT_DIR ...] [--sequences a,b,...]
BENCH_DIR is ../shared/bench, CACHE_DIR the generated sequences' cache (bench_accuracy.sh's
MILD_BENCH_CACHE). Sequences: every *.details.csv common to all OUT_DIRs but the hold-out seeds
(_s203, _s204) and scale walks, which are never used to choose anything.
"""
import glob
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import fit_scoring  # noqa: E402  (the scorer's fit and metrics, shared)


def sequence_dir(name, bench, cache):
    for candidate in (f"{bench}/real/{name}", f"{bench}/{name}", f"{cache}/{name}"):
        if os.path.exists(f"{candidate}/gt_loops.txt"):
            return candidate
    sys.exit(f"no sequence folder with gt_loops.txt for {name}")


def objective(runs, weights, bias):
    per_kind = {}
    for r in runs:
        m = fit_scoring.metrics(r, weights, bias)
        per_kind.setdefault(r["kind"], []).append((m["recall_at_100_precision"] + m["average_precision"]) / 2)
    return sum(sum(v) / len(v) for v in per_kind.values()) / len(per_kind)


def main():
    args = sys.argv[1:]
    only = None
    if "--sequences" in args:
        only = set(args[args.index("--sequences") + 1].split(","))
        del args[args.index("--sequences"):args.index("--sequences") + 2]
    if len(args) < 3:
        sys.exit(__doc__)
    bench, cache, specs = args[0], args[1], [a.split("=", 1) for a in args[2:]]
    names = None
    for _, out in specs:
        found = {os.path.basename(p)[:-len(".details.csv")] for p in glob.glob(f"{out}/*.details.csv")}
        names = found if names is None else names & found
    names = sorted(n for n in names if not n.endswith(("_s203", "_s204")) and not n.startswith("scale")
                   and (only is None or n in only))
    runs = {tag: [fit_scoring.load_run(f"{n}={sequence_dir(n, bench, cache)}:{out}/{n}.details.csv") for n in names]
            for tag, out in specs}
    kinds = sorted({r["kind"] for r in next(iter(runs.values()))})
    print("| left out | chosen (by the other kinds) | run | recall@100%P | AP | precision at the decision | recall at the decision |")
    print("|---|---|---|---|---|---|---|")
    for kind in kinds:
        best = None
        for tag, tag_runs in runs.items():
            training = [r for r in tag_runs if r["kind"] != kind]
            w, b = fit_scoring.fit(training, 0.01)
            score = objective(training, w, b)
            if best is None or score > best[0]:
                best = (score, tag, w, b)
        _, tag, w, b = best
        for r in (r for r in runs[tag] if r["kind"] == kind):
            m = fit_scoring.metrics(r, w, b)
            print(f"| {kind} | {tag} | {r['name']} | {m['recall_at_100_precision']:.3f} | "
                  f"{m['average_precision']:.3f} | {m['precision_at_decision']:.3f} ({m['wrong_at_decision']} wrong) | "
                  f"{m['recall_at_decision']:.3f} |")
    print("\n| configuration | objective on all kinds (mean over kinds of (recall@100%P + AP) / 2) |")
    print("|---|---|")
    for tag, tag_runs in runs.items():
        w, b = fit_scoring.fit(tag_runs, 0.01)
        print(f"| {tag} | {objective(tag_runs, w, b):.3f} |")


if __name__ == "__main__":
    main()
