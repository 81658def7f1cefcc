#!/usr/bin/python3
"""Prints mild_lcd's loop closures as they arrive and, given ground truth, scores them at the end.

ROS node. Subscribes to `loop_closure` (mild_lcd/LoopClosure). Private parameters:
  ~min_probability  print closures whose best candidate reaches this probability (default -1: those the
                    detector accepts, LoopCandidate.accepted, at its scoring/decision_probability)
  ~verified_only    score and print verified candidates only (default true, as mild_offline)
  ~every_keyframe   also print one line per keyframe: its best candidate or "no loop", features, time
  ~frames           exit after this many LoopClosure messages, printing the score (0: run until killed)
  ~gt               gt_loops.txt whose frame indices are the keyframe ids (default: none)
  ~config           the detector's configuration (YAML): the score's hard decision is at its
                    scoring/decision_probability (default: the built-in defaults, config/default.yaml's)
  ~min_gap          EVALUATION.md's minimum gap (default 40)
  ~output_csv       also write the scored rows query,candidate,score to this file
  ~idle_timeout     with ~frames set, give up this many seconds after the last message (default 30)
  ~result_file      write {"received", "frames", "scored", "ok"} here as JSON when done (roslaunch
                    exits 0 whatever a required node's exit code, so scripts read this instead)
"""
import json
import os
import subprocess
import sys
import tempfile
import time

import rospy
from mild_lcd.msg import LoopClosure


class Printer:
    def __init__(self):
        self.min_probability = float(rospy.get_param("~min_probability", -1.0))
        self.verified_only = rospy.get_param("~verified_only", True)
        self.frames = int(rospy.get_param("~frames", 0))
        self.every_keyframe = rospy.get_param("~every_keyframe", False)
        self.gt = rospy.get_param("~gt", "")
        self.config = rospy.get_param("~config", "")
        self.min_gap = int(rospy.get_param("~min_gap", 40))
        self.output_csv = rospy.get_param("~output_csv", "")
        self.idle_timeout = float(rospy.get_param("~idle_timeout", 30.0))
        self.result_file = rospy.get_param("~result_file", "")
        self.rows = []
        self.received = 0
        self.closures = 0
        self.last = time.monotonic()
        rospy.Subscriber("loop_closure", LoopClosure, self.on_loop_closure, queue_size=1000)

    def on_loop_closure(self, msg):
        self.received += 1
        self.last = time.monotonic()
        kept = [c for c in msg.candidates if c.verified or not self.verified_only]
        for c in kept:
            self.rows.append((msg.query_id, c.id, c.probability))
        if kept and (kept[0].accepted if self.min_probability < 0 else kept[0].probability >= self.min_probability):
            self.closures += 1
            c = kept[0]
            print(f"loop closure: keyframe {msg.query_id} -> {c.id}  probability {c.probability:.3f}  "
                  f"inliers {c.inliers}{' verified' if c.verified else ''}", flush=True)
        elif self.every_keyframe:
            best = (f"best {msg.candidates[0].id} p={msg.candidates[0].probability:.3f}"
                    f"{'' if msg.candidates[0].verified else ' unverified'}") if msg.candidates else "no candidate"
            total_ms = msg.extract_ms + msg.query_ms + msg.filter_ms + msg.verify_ms
            print(f"keyframe {msg.query_id}: no loop ({best}; {msg.features} features, "
                  f"{msg.database_size} stored, {total_ms:.1f} ms)", flush=True)

    def done(self):
        if self.frames <= 0:
            return False
        return self.received >= self.frames or time.monotonic() - self.last > self.idle_timeout

    def report(self):
        """Prints the summary and, given ground truth, the score; False when scoring failed."""
        rule = "accepted by the detector" if self.min_probability < 0 else f"at probability >= {self.min_probability}"
        print(f"processed {self.received} keyframes, {self.closures} loop closures {rule}", flush=True)
        path = self.output_csv or os.path.join(tempfile.mkdtemp(prefix="mild_lcd_"), "candidates.csv")
        with open(path, "w") as f:
            f.write("query,candidate,score\n")
            for q, c, p in self.rows:
                f.write(f"{q},{c},{p:.10g}\n")
        if self.gt:
            config = ["--config", self.config] if self.config else []
            score = subprocess.run(["rosrun", "mild_lcd", "mild_score", self.gt, path, "--min-gap", str(self.min_gap)]
                                   + config,
                                   capture_output=True, text=True)
            print("score against " + self.gt + ":\n" + (score.stdout or score.stderr).rstrip(), flush=True)
            if score.returncode != 0:
                print(f"scoring failed (mild_score exit code {score.returncode})", file=sys.stderr, flush=True)
                return False
        return True


def main():
    rospy.init_node("loop_closure_printer")
    printer = Printer()
    rate = rospy.Rate(10) if not rospy.get_param("/use_sim_time", False) else None
    while not rospy.is_shutdown() and not printer.done():
        if rate:
            rate.sleep()
        else:
            time.sleep(0.1)  # sim time may stand still once the bag ends
    scored = printer.report()
    complete = printer.frames <= 0 or printer.received >= printer.frames
    if not complete:
        print(f"only {printer.received} of {printer.frames} keyframes were answered", file=sys.stderr, flush=True)
    if printer.result_file:
        with open(printer.result_file, "w") as f:
            json.dump({"received": printer.received, "frames": printer.frames, "scored": scored,
                       "ok": scored and complete}, f)
    if not (scored and complete):
        sys.exit(1)


if __name__ == "__main__":
    main()
