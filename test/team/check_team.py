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
Robot6's second revisit, after the restart, replays its frames under ids --revisit-id-offset (1000)
above theirs: such an id is judged as its frame (id - 1000). (a), (d) and the recall are over the
first part of the run (ids below the offset), as the reference has no second revisit.

  (a) recall against the reference: of the (query robot, query id, candidate robot) for which the
      reference accepted a right inter-group loop, the distributed run accepted a right one for at
      least --min-coverage (95 %)
  (b) the distributed run accepted no wrong inter-group loop
  (c) each distributed inter-group loop (query robot, query id, candidate robot, candidate id) came
      at most once per robot topic in each recorder's file (a recorder sees each message once: twice
      in one file is a double report), and on both robots' topics (in any file)
  (d) printed: robot6's keyframes made while host 3 was cut off (answered by their station between
      the cut and the restore) and their inter-group loops, found only after the restore
  (e) printed, from the last /mild_team/status of each station (and of the restarted one's run
      before the restart): summaries taken and bytes per summary, whole keyframes pulled (replies
      to its pulls) and bytes per reply, beside what forwarding each robot's whole Keyframe to one base station would cost
      per keyframe (the Keyframe messages' serialized size in --bags, mean per keyframe); and the
      loops each station found late (for a keyframe taken after a gap)
  (f) with --restarted: the station restarted (SIGTERM, then started again on its saved maps and
      ledger) rejoins without a loop lost or repeated:
      (f1) its first status after the restart continues its count of summaries (as many as in its
           last status before it; its last one, that many more as its robots' keyframes since)
           and takes, per peer, no fewer summaries and loops than before; its robot's first
           answers after it count the map it had (database_size), so the maps were read back
      (f2) the summaries it took after the restart (its summaries_in, counted from its start) are
           at most those its peers numbered since its last status before it: none re-sent; and
           printed, what each peer took after the restart, against what was new
      (f3) robot6's second revisit (ids offset + 250..299) has a right inter-group loop for at
           least --min-coverage (95 %) of the keyframes for which its first revisit had one
           (judged as frames, id - offset), and no wrong one
      (f4) no loop (any accepted candidate, inter- or intra-group) came twice on a topic over the
           whole run: counted per recorder, as a recorder sees each message once (two recorders
           seeing one message are two files, never summed; a message published twice is twice in
           each recorder that was connected both times)
  and printed for both runs: keyframes answered per robot, recall@100%P of the inter-robot pairs.
Exits 1 when (a), (b), (c) or (f) fails or the keyframe ids are not the robots' frames.

  check_team.py --gt gt_loops.txt --reference ref.jsonl --distributed host1.jsonl host3.jsonl
                [--events events.json] [--bags robot1.bag ...] [--revisit-id-offset 1000]
                [--restarted charlie --status-before-restart status_before_restart.json]
"""
import argparse
import collections
import json
import sys

STATION_OF = {"robot1": "alpha", "robot2": "alpha", "robot3": "bravo", "robot4": "bravo",
              "robot5": "charlie", "robot6": "charlie"}
FRAMES_PER_ROBOT = 50
MIN_GAP = 40  # EVALUATION.md's: pairs closer than this are not scored
REVISIT_ID_OFFSET = 1000  # --revisit-id-offset: ids from here on are a second revisit's


def frame_of(keyframe_id):
    """The sample frame a keyframe id shows (a second revisit's ids are its frames + the offset)."""
    return keyframe_id - REVISIT_ID_OFFSET if keyframe_id >= REVISIT_ID_OFFSET else keyframe_id


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
        """Two keyframe ids (a second revisit's judged as their frames)."""
        a, b = frame_of(a), frame_of(b)
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


def first_part(records):
    """The records of the run up to the second revisit: its queries, and candidates, left out."""
    kept = []
    for r in records:
        if r["kind"] == "loop":
            if r["query_id"] >= REVISIT_ID_OFFSET:
                continue
            r = dict(r, candidates=[c for c in r["candidates"] if c["id"] < REVISIT_ID_OFFSET])
        kept.append(r)
    return kept


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

    def count(robot):
        first = sum(1 for i in seen[robot] if i < REVISIT_ID_OFFSET)
        again = len(seen[robot]) - first
        return f"{robot} {first}/{FRAMES_PER_ROBOT}" + (f" (+{again} of a second revisit)" if again else "")
    print(f"{name}: keyframes answered on their own topic: " + ", ".join(count(robot) for robot in sorted(STATION_OF)))


def check_ids(name, records):
    """Keyframe ids must be the frames of their robot's part of the sample, or nothing here holds."""
    bad = [(r["query_robot"], r["query_id"]) for r in records
           if r["kind"] == "loop" and robot_of_frame(frame_of(r["query_id"])) != r["query_robot"]]
    bad += [(c["robot"], c["id"]) for _, c in loop_candidates(records)
            if robot_of_frame(frame_of(c["id"])) != c["robot"]]
    if bad:
        print(f"FAIL (ids) {name}: {len(bad)} keyframe ids are not their robot's frames, e.g. {bad[:5]}")
    return not bad


def statuses_of(records, station):
    """(arrival time, fields) of a station's statuses, in arrival order."""
    return [(r["received"], r["fields"]) for r in records
            if r["kind"] == "status" and r["fields"].get("station") == station]


def per_peer(fields, name):
    """peer -> the value of a per-peer list (received, loops_received) in a status."""
    return dict(zip(fields.get("peers", []), fields.get(name, [])))


def keyframe_bytes(paths):
    """robot -> serialized sizes of the mild_lcd/Keyframe messages in its bags."""
    import rosbag  # Debian's, for /usr/bin/python3; only needed with --bags
    sizes = collections.defaultdict(list)
    for path in paths:
        with rosbag.Bag(path) as bag:
            for topic, raw, _ in bag.read_messages(raw=True):
                if raw[0] == "mild_lcd/Keyframe":
                    sizes[topic.strip("/").split("/")[0]].append(len(raw[1]))
    return sizes


def check_restart(args, truth, distributed, recorders, events):
    """(f): the restarted station rejoins without a loop lost or repeated. True when it holds."""
    station = args.restarted
    ok = True
    with open(args.status_before_restart, encoding="utf-8") as f:
        before_all = json.load(f)
    if station not in before_all:
        print(f"FAIL (f) no status of {station} before the restart")
        return False
    before = before_all[station]["fields"]
    after = [(t, fields) for t, fields in statuses_of(distributed, station) if t > events["restart_start"]]
    if not after:
        print(f"FAIL (f) no status of {station} after the restart")
        return False
    first, final = after[0][1], after[-1][1]
    robots = sorted(robot for robot, s in STATION_OF.items() if s == station)

    # (f1) Its counts continue; its maps were read back.
    own = lambda r: all(c["station"] == station for c in r["candidates"])  # noqa: E731 (its own answer)
    revisit_answered = {r["query_id"] for r in distributed if r["kind"] == "loop" and r["query_id"] >= REVISIT_ID_OFFSET
                        and r["topic"] == f"/{r['query_robot']}/loop_closure" and own(r)}
    behind = {peer: (n, per_peer(first, "received").get(peer, 0)) for peer, n in per_peer(before, "received").items()
              if per_peer(first, "received").get(peer, 0) < n}
    loops_behind = {peer: (n, per_peer(first, "loops_received").get(peer, 0))
                    for peer, n in per_peer(before, "loops_received").items()
                    if per_peer(first, "loops_received").get(peer, 0) < n}
    sizes = {}  # robot -> (largest database_size of its own answers before the restart, smallest after)
    for robot in robots:
        own_answers = [r for r in distributed if r["kind"] == "loop" and r["topic"] == f"/{robot}/loop_closure"
                       and r["query_robot"] == robot and own(r)]
        before_size = max((r["database_size"] for r in own_answers if r["received"] < events["restart_sigterm"]),
                          default=0)
        after_size = min((r["database_size"] for r in own_answers if r["received"] > events["restart_start"]),
                         default=None)
        sizes[robot] = (before_size, after_size)
    maps_read = all(a is None or a > b for b, a in sizes.values()) and any(a is not None for _, a in sizes.values())
    good = (first["summaries"] == before["summaries"] and
            final["summaries"] == before["summaries"] + len(revisit_answered) and
            not behind and not loops_behind and maps_read)
    print(f"{'ok' if good else 'FAIL'} (f1) {station}'s summaries: {before['summaries']} before the restart, "
          f"{first['summaries']} in its first status after it, {final['summaries']} at the end "
          f"({len(revisit_answered)} keyframes of the second revisit answered, as many wanted more); "
          f"taken per peer before / after: " +
          ", ".join(f"{p} {n} / {per_peer(first, 'received').get(p, 0)}" for p, n in sorted(per_peer(before, 'received').items())) +
          "; loops taken per peer before / after: " +
          ", ".join(f"{p} {n} / {per_peer(first, 'loops_received').get(p, 0)}"
                    for p, n in sorted(per_peer(before, "loops_received").items())) +
          "; own map before the restart / first answer after it (database_size): " +
          ", ".join(f"{robot} {b} / {a if a is not None else '-'}" for robot, (b, a) in sorted(sizes.items())))
    if behind or loops_behind:
        print(f"    below what it had before the restart (before, after): summaries {behind}, loops {loops_behind}")
    ok &= good

    # (f2) Nothing re-sent to it; what its peers took from it after the restart, beside what was new.
    new_for_it = 0
    for peer, had in per_peer(before, "received").items():
        peer_final = statuses_of(distributed, peer)
        new_for_it += max(0, (peer_final[-1][1]["summaries"] if peer_final else had) - had)
    good = final["summaries_in"] <= new_for_it
    print(f"{'ok' if good else 'FAIL'} (f2) summaries {station} took after the restart: {final['summaries_in']} "
          f"({final['summary_bytes_in']} bytes); its peers numbered {new_for_it} new ones since its last status "
          f"before it (more taken than new would be re-sent)")
    ok &= good
    new_of = {name: (statuses_of(distributed, name)[-1][1]["summaries"] if statuses_of(distributed, name) else 0) -
              fields["fields"]["summaries"] for name, fields in before_all.items()}
    for peer in sorted(before_all):
        if peer == station or not statuses_of(distributed, peer):
            continue
        took = statuses_of(distributed, peer)[-1][1]["summaries_in"] - before_all[peer]["fields"]["summaries_in"]
        new = sum(n for name, n in new_of.items() if name != peer)
        print(f"    {peer} took {took} summaries after the restart; the other stations numbered {new} new ones "
              f"(a difference is copies: a broadcast and a gap's filling both bringing one)")

    # (f3) The second revisit's inter-group loops, against the first's.
    def right_queries(records, revisit):
        return {frame_of(r["query_id"]) for r, c in accepted_inter_group(records)
                if r["query_robot"] == "robot6" and (r["query_id"] >= REVISIT_ID_OFFSET) == revisit
                and truth.judge(r["query_id"], c["id"]) == "right"}
    first_found, again_found = right_queries(distributed, False), right_queries(distributed, True)
    judged = collections.defaultdict(set)
    for r, c in accepted_inter_group(distributed):
        if r["query_id"] >= REVISIT_ID_OFFSET or c["id"] >= REVISIT_ID_OFFSET:
            judged[truth.judge(r["query_id"], c["id"])].add(loop_key(r, c))
    coverage = len(first_found & again_found) / len(first_found) if first_found else 0.0
    good = bool(first_found) and coverage >= args.min_coverage - 1e-9 and not judged["wrong"]
    print(f"{'ok' if good else 'FAIL'} (f3) robot6 keyframes with a right inter-group loop: first revisit "
          f"{len(first_found)}, second revisit (after the restart) {len(again_found)}, of the first's "
          f"{len(first_found & again_found)} ({100 * coverage:.1f} %, at least {100 * args.min_coverage:.0f} % wanted); "
          f"its inter-group loops: {len(judged['right'])} right, {len(judged['wrong'])} wrong, "
          f"{len(judged['dont_care'])} don't care, {len(judged['near'])} not judged")
    if first_found - again_found:
        print("    found on the first revisit only (frames):", sorted(first_found - again_found))
    if judged["wrong"]:
        print("    wrong (query robot, id, candidate robot, id):", sorted(judged["wrong"])[:20])
    if "revisit_start" in events:
        times = [r["received"] - events["revisit_start"] for r, c in accepted_inter_group(distributed)
                 if r["query_id"] >= REVISIT_ID_OFFSET]
        if times:
            print(f"    received {min(times):.1f} .. {max(times):.1f} s after the second revisit began")

    # (f4) No loop twice on a topic, per recorder.
    doubles = []
    loops = 0
    for path, records in recorders.items():
        arrivals = collections.defaultdict(list)
        for r, c in loop_candidates(records):
            if c["accepted"]:
                arrivals[(r["topic"],) + loop_key(r, c)].append(r["received"])
        loops = max(loops, len(arrivals))
        doubles += [(path, key, times) for key, times in sorted(arrivals.items()) if len(times) > 1]
    good = not doubles
    print(f"{'ok' if good else 'FAIL'} (f4) loops (accepted candidates, any group) on a topic, per recorder, "
          f"over the whole run: {', '.join(f'{p.rsplit(chr(47), 1)[-1]} {n}' for p, n in loop_counts(recorders))}; "
          f"reported twice: {len(doubles)}")
    for path, key, times in doubles[:10]:
        print(f"    {len(times)} times in {path}: {key}, received " +
              ", ".join(f"{t - events.get('t0', 0):.1f}" for t in times) + " s after t0")
    ok &= good
    return ok


def loop_counts(recorders):
    """(recorder file, distinct loops on a topic it saw)."""
    for path, records in recorders.items():
        yield path, len({(r["topic"],) + loop_key(r, c) for r, c in loop_candidates(records) if c["accepted"]})


def print_bytes(distributed, args, events):
    """(e): what the team link cost, against forwarding the robots' whole keyframes."""
    last = {}  # station (and run) -> its last status: the counts are over its run
    for r in distributed:
        if r["kind"] == "status":
            last[r["fields"].get("station", r["recorder"])] = r["fields"]
    if not last:
        print("(e) no status recorded")
        return
    rows = []
    before = {}
    if args.restarted and args.status_before_restart:
        with open(args.status_before_restart, encoding="utf-8") as f:
            before = json.load(f)
    for station, fields in sorted(last.items()):
        if station == args.restarted and station in before:
            rows.append((f"{station} (before restart)", before[station]["fields"]))
            rows.append((f"{station} (after restart)", fields))
        else:
            rows.append((station, fields))
    sizes = keyframe_bytes(args.bags) if args.bags else {}
    every = [n for robot in sizes for n in sizes[robot]]
    whole = sum(every) / len(every) if every else 0.0
    print("(e) bytes in, from each station's last status (each run of the restarted station counts from its start);")
    print("    pulled: TeamFeatures replies to its pulls of a whole keyframe (a BUSY refusal, asked again, counts too):")
    print(f"    {'station':<26} {'summaries':>9} {'B/summary':>9} {'pulled':>6} {'B/pulled':>8} "
          f"{'B in per peer keyframe':>22} {'whole Keyframe B':>16}")
    for name, f in rows:
        per_summary = f["summary_bytes_in"] / f["summaries_in"] if f["summaries_in"] else 0.0
        per_pull = f["feature_bytes_in"] / f["features_in"] if f["features_in"] else 0.0
        per_keyframe = (f["summary_bytes_in"] + f["feature_bytes_in"]) / f["summaries_in"] if f["summaries_in"] else 0.0
        print(f"    {name:<26} {f['summaries_in']:>9} {per_summary:>9.0f} {f['features_in']:>6} {per_pull:>8.0f} "
              f"{per_keyframe:>22.0f} {whole:>16.0f}")
    if every:
        print("    whole Keyframe messages in the bags (serialized, mean per keyframe): " +
              ", ".join(f"{robot} {sum(n) / len(n):.0f}" for robot, n in sorted(sizes.items())) +
              f"; all {len(every)}: {whole:.0f} B, what one base station would take per keyframe forwarded whole")
        taken = sum(f["summaries_in"] for _, f in rows)
        paid = sum(f["summary_bytes_in"] + f["feature_bytes_in"] for _, f in rows)
        if taken:
            print(f"    the team link over the run: {paid} B for {taken} keyframes taken by a peer, "
                  f"{paid / taken:.0f} B each ({100 * paid / taken / whole:.1f} % of a whole Keyframe)")
    print("(e) loops decided by each station / of them found late (for a keyframe taken after a gap): " +
          ", ".join(f"{name} {f['loops_decided']} / {f['loops_found_late']}" for name, f in rows))


def main():
    global REVISIT_ID_OFFSET
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--gt", required=True, help="the sample's gt_loops.txt")
    parser.add_argument("--reference", required=True, help="the reference run's recording")
    parser.add_argument("--distributed", required=True, nargs="+", help="the distributed run's, one per recorder")
    parser.add_argument("--events", help="three_hosts.sh's events.json (wall-clock times of the cut and restore)")
    parser.add_argument("--min-coverage", type=float, default=0.95)
    parser.add_argument("--revisit-id-offset", type=int, default=REVISIT_ID_OFFSET,
                        help="keyframe ids from here on are a second revisit's: frame = id - offset")
    parser.add_argument("--restarted", help="the station restarted (check f)")
    parser.add_argument("--status-before-restart", help="each station's last status before it (JSON)")
    parser.add_argument("--bags", nargs="*", default=[], help="the robots' bags (a whole Keyframe's size)")
    args = parser.parse_args()
    REVISIT_ID_OFFSET = args.revisit_id_offset
    if args.restarted and not (args.events and args.status_before_restart):
        parser.error("--restarted needs --events and --status-before-restart")

    truth = Truth(args.gt)
    reference = read(args.reference)
    recorders = {path: read(path) for path in args.distributed}
    distributed = [r for records in recorders.values() for r in records]
    first = first_part(distributed)
    ok = check_ids("reference", reference) & check_ids("distributed", distributed)
    events = {}
    if args.events:
        with open(args.events, encoding="utf-8") as f:
            events = json.load(f)

    print_answered("reference", reference)
    print_answered("distributed", distributed)
    for name, records in (("reference", reference), ("distributed (before the second revisit)", first)):
        recall, frames = recall_at_full_precision(truth, records)
        print(f"{name}: recall@100%P of the inter-robot pairs {recall:.3f} (over {frames} loop frames)")

    # (a) The reference's right inter-group loops, per query keyframe and map, found again.
    def right_keys(records):
        return {(r["query_robot"], r["query_id"], c["robot"]) for r, c in accepted_inter_group(records)
                if truth.judge(r["query_id"], c["id"]) == "right"}
    wanted, found = right_keys(reference), right_keys(first)
    covered = wanted & found
    coverage = len(covered) / len(wanted) if wanted else 0.0
    good = bool(wanted) and coverage >= args.min_coverage - 1e-9  # 57 of 60 is 95 %
    print(f"{'ok' if good else 'FAIL'} (a) reference query keyframes with a right inter-group loop: {len(wanted)}; "
          f"the distributed run has one for {len(covered)} ({100 * coverage:.1f} %, at least "
          f"{100 * args.min_coverage:.0f} % wanted); it has {len(found - wanted)} more the reference has not")
    if wanted - found:
        print("    missing (query robot, id, map):", sorted(wanted - found)[:20])
    ok &= good

    # (b) No wrong inter-group loop accepted (over the whole run).
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
    if events:
        outage = {r["query_id"] for r in first
                  if r["kind"] == "loop" and r["query_robot"] == "robot6" and r["topic"] == "/robot6/loop_closure"
                  and events["cut"] <= r["received"] < events["restore"]}
        first_seen = {}
        for r, c in accepted_inter_group(first):
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
    print_bytes(distributed, args, events)

    # (f) The restart.
    if args.restarted:
        ok &= check_restart(args, truth, distributed, recorders, events)

    print("PASS" if ok else "FAIL")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
