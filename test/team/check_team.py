#!/usr/bin/python3
"""Checks the loops three mild_lcd stations found between their groups against one node's and the truth.

Reads the JSON lines of test/team/record_loops.py: the reference run's (one node serving robot1..6)
and the distributed run's, one file per recorder. Keyframe ids are frame indices of the sample
(robot r replays frames [50(r-1), 50r)), so a pair of ids is judged by gt_loops.txt directly, as
src/offline/evaluation.cpp does: a listed pair with is_true 1 is right, with is_true 0 don't care,
any other pair wrong; a pair is looked up as (larger id, smaller id), whichever keyframe was the query.
Pairs fewer than 40 frames apart are not judged (the ground truth lists none, and evaluation.cpp
drops them as min_gap): at the robots' seams, robot2's frame 99 and robot3's frame 100 are one place.
A loop is an accepted candidate; inter-group when its two robots belong to different stations.

  (a) recall against the reference: of the (query robot, query id, candidate robot) for which the
      reference accepted a right inter-group loop, the distributed run accepted a right one for at
      least --min-coverage (95 %)
  (b) the distributed run accepted no wrong inter-group loop
  (c) each distributed inter-group loop (query robot, query id, candidate robot, candidate id) came
      at most once per robot topic in each recorder's file (a recorder sees each message once: twice
      in one file is a double report), and on both robots' topics (in any file)
  (d) printed: robot6's keyframes made while host 3 was cut off (answered by their station between
      the cut and the restore) and their inter-group loops, found only after the restore
  (e) printed: the byte counts in the last /mild_team/status message of each station, if recorded
  and printed for both runs: keyframes answered per robot, recall@100%P of the inter-robot pairs.
Exits 1 when (a), (b), (c) fails or the keyframe ids are not the robots' frames.

  check_team.py --gt gt_loops.txt --reference ref.jsonl --distributed host1.jsonl host3.jsonl
                [--events events.json]
"""
import argparse
import collections
import json
import sys

STATION_OF = {"robot1": "alpha", "robot2": "alpha", "robot3": "bravo", "robot4": "bravo",
              "robot5": "charlie", "robot6": "charlie"}
FRAMES_PER_ROBOT = 50
MIN_GAP = 40  # EVALUATION.md's: pairs closer than this are not scored


class Truth:
    """gt_loops.txt: lines 'i j overlap is_true', blank lines and '#' comments skipped."""

    def __init__(self, path):
        self.right, self.dont_care = set(), set()
        with open(path, encoding="utf-8") as f:
            for line in f:
                fields = line.split()
                if not fields or fields[0].startswith("#"):
                    continue
                pair = (int(fields[0]), int(fields[1]))
                (self.right if fields[3] == "1" else self.dont_care).add(pair)

    def judge(self, a, b):
        pair = (max(a, b), min(a, b))
        if pair[0] - pair[1] < MIN_GAP:
            return "near"
        if pair in self.right:
            return "right"
        return "dont_care" if pair in self.dont_care else "wrong"


def robot_of_frame(frame):
    return f"robot{frame // FRAMES_PER_ROBOT + 1}"


def read(path):
    """The records of one recorder's file, in arrival order."""
    with open(path, encoding="utf-8") as f:
        return [json.loads(line) for line in f if line.strip()]


def loop_candidates(records):
    """(record, candidate) for every candidate of every loop_closure record."""
    for r in records:
        if r["kind"] == "loop":
            for c in r["candidates"]:
                yield r, c


def inter_group(r, c):
    return STATION_OF[r["query_robot"]] != STATION_OF[c["robot"]]


def accepted_inter_group(records):
    return [(r, c) for r, c in loop_candidates(records) if c["accepted"] and inter_group(r, c)]


def loop_key(r, c):
    return (r["query_robot"], r["query_id"], c["robot"], c["id"])


def answered(records):
    """robot -> its keyframes answered on its own topic."""
    seen = collections.defaultdict(set)
    for r in records:
        if r["kind"] == "loop" and r["topic"] == f"/{r['query_robot']}/loop_closure":
            seen[r["query_robot"]].add(r["query_id"])
    return seen


def recall_at_full_precision(truth, records):
    """recall@100%P of the inter-robot pairs, as mild::evaluate: each frame's best-scoring candidate
    (the first seen wins a tie) ranked by probability, equal scores entering together; the recall
    at the last step without a wrong candidate, over the frames with a right inter-robot pair."""
    best = {}
    for r, c in loop_candidates(records):
        if c["robot"] == r["query_robot"]:
            continue
        i, j = max(r["query_id"], c["id"]), min(r["query_id"], c["id"])
        if i - j < MIN_GAP:
            continue
        if i not in best or c["probability"] > best[i][2]:
            best[i] = (i, j, c["probability"])
    loop_frames = {i for i, j in truth.right if robot_of_frame(i) != robot_of_frame(j)}
    ranked = sorted(best.values(), key=lambda p: -p[2])  # stable: ties keep arrival order
    hit, wrong, recall, k = set(), 0, 0.0, 0
    while k < len(ranked):
        score = ranked[k][2]
        while k < len(ranked) and ranked[k][2] == score:
            verdict = truth.judge(ranked[k][0], ranked[k][1])
            if verdict == "right":
                hit.add(ranked[k][0])
            elif verdict == "wrong":
                wrong += 1
            k += 1
        if wrong == 0:
            recall = len(hit) / max(1, len(loop_frames))
    return recall, len(loop_frames)


def print_answered(name, records):
    seen = answered(records)
    print(f"{name}: keyframes answered on their own topic: " +
          ", ".join(f"{robot} {len(seen[robot])}/{FRAMES_PER_ROBOT}" for robot in sorted(STATION_OF)))


def check_ids(name, records):
    """Keyframe ids must be the frames of their robot's part of the sample, or nothing here holds."""
    bad = [(r["query_robot"], r["query_id"]) for r in records
           if r["kind"] == "loop" and robot_of_frame(r["query_id"]) != r["query_robot"]]
    bad += [(c["robot"], c["id"]) for _, c in loop_candidates(records) if robot_of_frame(c["id"]) != c["robot"]]
    if bad:
        print(f"FAIL (ids) {name}: {len(bad)} keyframe ids are not their robot's frames, e.g. {bad[:5]}")
    return not bad


def flatten(fields, prefix=""):
    """(dotted name, value) of every scalar in a recorded message."""
    for name, value in fields.items():
        if isinstance(value, dict):
            yield from flatten(value, f"{prefix}{name}.")
        else:
            yield f"{prefix}{name}", value


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--gt", required=True, help="the sample's gt_loops.txt")
    parser.add_argument("--reference", required=True, help="the reference run's recording")
    parser.add_argument("--distributed", required=True, nargs="+", help="the distributed run's, one per recorder")
    parser.add_argument("--events", help="three_hosts.sh's events.json (wall-clock times of the cut and restore)")
    parser.add_argument("--min-coverage", type=float, default=0.95)
    args = parser.parse_args()

    truth = Truth(args.gt)
    reference = read(args.reference)
    recorders = {path: read(path) for path in args.distributed}
    distributed = [r for records in recorders.values() for r in records]
    ok = check_ids("reference", reference) & check_ids("distributed", distributed)

    print_answered("reference", reference)
    print_answered("distributed", distributed)
    for name, records in (("reference", reference), ("distributed", distributed)):
        recall, frames = recall_at_full_precision(truth, records)
        print(f"{name}: recall@100%P of the inter-robot pairs {recall:.3f} (over {frames} loop frames)")

    # (a) The reference's right inter-group loops, per query keyframe and map, found again.
    def right_keys(records):
        return {(r["query_robot"], r["query_id"], c["robot"]) for r, c in accepted_inter_group(records)
                if truth.judge(r["query_id"], c["id"]) == "right"}
    wanted, found = right_keys(reference), right_keys(distributed)
    covered = wanted & found
    coverage = len(covered) / len(wanted) if wanted else 0.0
    good = bool(wanted) and coverage >= args.min_coverage - 1e-9  # 57 of 60 is 95 %
    print(f"{'ok' if good else 'FAIL'} (a) reference query keyframes with a right inter-group loop: {len(wanted)}; "
          f"the distributed run has one for {len(covered)} ({100 * coverage:.1f} %, at least "
          f"{100 * args.min_coverage:.0f} % wanted); it has {len(found - wanted)} more the reference has not")
    if wanted - found:
        print("    missing (query robot, id, map):", sorted(wanted - found)[:20])
    ok &= good

    # (b) No wrong inter-group loop accepted.
    judged = collections.defaultdict(set)
    for r, c in accepted_inter_group(distributed):
        judged[truth.judge(r["query_id"], c["id"])].add(loop_key(r, c))
    wrong = sorted(judged["wrong"])
    print(f"{'ok' if not wrong else 'FAIL'} (b) accepted inter-group loops of the distributed run: "
          f"{len(judged['right'])} right, {len(wrong)} wrong, {len(judged['dont_care'])} don't care, "
          f"{len(judged['near'])} fewer than {MIN_GAP} frames apart (not judged)")
    if wrong:
        print("    wrong (query robot, id, candidate robot, id):", wrong[:20])
    ok &= not wrong

    # (c) Once per robot topic (per recorder), and on both robots' topics (over the recorders).
    doubles = []
    topics = collections.defaultdict(set)
    for path, records in recorders.items():
        count = collections.Counter((r["topic"],) + loop_key(r, c) for r, c in accepted_inter_group(records))
        doubles += [(path, key, n) for key, n in count.items() if n > 1]
        for topic, *key in count:
            topics[tuple(key)].add(topic)
    one_sided = sorted(key for key, seen in topics.items()
                       if not {f"/{key[0]}/loop_closure", f"/{key[2]}/loop_closure"} <= seen)
    both_ways = {frozenset([key[:2], key[2:]]) for key in topics}
    good = not doubles and not one_sided
    print(f"{'ok' if good else 'FAIL'} (c) distributed inter-group loops: {len(topics)}; reported twice on a topic: "
          f"{len(doubles)}; missing from one robot's topic: {len(one_sided)}; "
          f"(pairs also reported with query and candidate swapped: {len(topics) - len(both_ways)})")
    for path, key, n in doubles[:10]:
        print(f"    {n} times in {path}: {key}")
    if one_sided:
        print("    on one topic only:", [(key, sorted(topics[key])) for key in one_sided[:10]])
    ok &= good

    # (d) robot6's revisit made during the outage: its loops into the other groups' maps come after it.
    if args.events:
        with open(args.events, encoding="utf-8") as f:
            events = json.load(f)
        outage = {r["query_id"] for r in distributed
                  if r["kind"] == "loop" and r["query_robot"] == "robot6" and r["topic"] == "/robot6/loop_closure"
                  and events["cut"] <= r["received"] < events["restore"]}
        first_seen = {}
        for r, c in accepted_inter_group(distributed):
            if r["query_robot"] == "robot6" and r["query_id"] in outage and \
                    truth.judge(r["query_id"], c["id"]) == "right":
                first_seen[r["query_id"]] = min(first_seen.get(r["query_id"], r["received"]), r["received"])
        after = sum(1 for t in first_seen.values() if t >= events["restore"])
        in_reference = {qid for robot, qid, _ in wanted if robot == "robot6" and qid in outage}
        print(f"(d) robot6 keyframes made during the outage: {len(outage)}; with a right inter-group loop: "
              f"{len(first_seen)} (reference: {len(in_reference)}), first received after the restore: {after}")
        if first_seen:
            delays = sorted(t - events["restore"] for t in first_seen.values())
            print(f"    received {delays[0]:.1f} .. {delays[-1]:.1f} s after the restore")

    # (e) What the team link cost, as the stations count it.
    statuses = [r for r in distributed if r["kind"] == "status"]
    if not statuses:
        print("(e) no status recorded")
    else:
        last = {}  # station -> its last status: the counts are over its run
        for r in statuses:
            last[r["fields"].get("station", r["recorder"])] = r["fields"]
        totals = collections.Counter()
        for station, fields in sorted(last.items()):
            # Byte counts (summary_bytes_in, ...), not widths (descriptor_bytes).
            sizes = {name: value for name, value in flatten(fields) if "bytes_" in name}
            totals.update(sizes)
            print(f"(e) {station}: " + (", ".join(f"{n} {v}" for n, v in sorted(sizes.items())) or "no byte counts"))
        print("(e) all stations: " + ", ".join(f"{n} {v}" for n, v in sorted(totals.items())))

    print("PASS" if ok else "FAIL")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
