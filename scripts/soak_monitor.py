#!/usr/bin/python3
"""Watches a running mild_lcd during the soak test (scripts/soak.sh) and writes its report.

Samples, every ~period seconds: keyframes answered on loop_closure, their query times, the resident
memory of the process that hosts the nodelet, and the nodelet's diagnostics (database size, queue
depth, dropped and rejected keyframes). At the end (after ~duration seconds) it prints and writes
(~report, JSON): memory growth per keyframe (least squares of RSS against database size), drops,
and the drift of the query time from the first to the last minute.
"""
import json
import os
import statistics
import time

import rospy
from diagnostic_msgs.msg import DiagnosticArray
from mild_lcd.msg import LoopClosure


def rss_bytes(pid):
    with open(f"/proc/{pid}/status") as f:
        for line in f:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) * 1024
    return 0


def slope(xs, ys):
    mx, my = statistics.fmean(xs), statistics.fmean(ys)
    den = sum((x - mx) ** 2 for x in xs)
    return sum((x - mx) * (y - my) for x, y in zip(xs, ys)) / den if den > 0 else 0.0


class Monitor:
    def __init__(self):
        self.pid = int(rospy.get_param("~pid"))
        self.duration = float(rospy.get_param("~duration", 600))
        self.period = float(rospy.get_param("~period", 5))
        self.report_path = rospy.get_param("~report", "")
        self.answers = []   # (wall time, query_ms, database_size, extract_ms, filter_ms, verify_ms)
        self.diag = {}
        self.samples = []   # (wall time, rss, database size, queue depth, dropped)
        rospy.Subscriber("loop_closure", LoopClosure, self.on_answer, queue_size=1000)
        rospy.Subscriber("/diagnostics", DiagnosticArray, self.on_diagnostics, queue_size=10)

    def on_answer(self, msg):
        self.answers.append((time.monotonic(), msg.query_ms, msg.database_size, msg.extract_ms, msg.filter_ms,
                             msg.verify_ms))

    def on_diagnostics(self, msg):
        for status in msg.status:
            if "loop closure detector" in status.name:
                self.diag = {kv.key: kv.value for kv in status.values}

    def run(self):
        start = time.monotonic()
        while not rospy.is_shutdown() and time.monotonic() - start < self.duration:
            time.sleep(self.period)
            size = self.answers[-1][2] if self.answers else 0
            self.samples.append((time.monotonic() - start, rss_bytes(self.pid), size,
                                 int(self.diag.get("queue depth", 0)), int(self.diag.get("dropped keyframes", 0))))
        return self.report(start)

    def report(self, start):
        if len(self.answers) < 2 or len(self.samples) < 3:
            return {"error": "too few answers or samples"}
        elapsed = self.answers[-1][0] - self.answers[0][0]
        first = [a[1] for a in self.answers if a[0] - start < 60]
        last = [a[1] for a in self.answers if a[0] - start > self.duration - 60]
        grown = [(s[2], s[1]) for s in self.samples if s[2] > 0]
        report = {
            "duration_s": round(self.duration),
            "keyframes_answered": len(self.answers),
            "rate_hz": round(len(self.answers) / elapsed, 2) if elapsed > 0 else None,
            "database_keyframes": self.answers[-1][2],
            "dropped_keyframes": int(self.diag.get("dropped keyframes", -1)),
            "rejected_keyframes": int(self.diag.get("rejected keyframes", -1)),
            "max_queue_depth": max(s[3] for s in self.samples),
            "rss_start_mb": round(self.samples[0][1] / 1e6, 1),
            "rss_end_mb": round(self.samples[-1][1] / 1e6, 1),
            # What the detector itself accounts for (arrays at their capacity); RSS also holds the
            # allocator's freed copies of arrays that grew, the libraries and the message buffers.
            "database_memory_mb": float(self.diag.get("memory (MB)", "nan")),
            "memory_growth_bytes_per_keyframe": round(slope([g[0] for g in grown], [g[1] for g in grown])),
            "query_ms_first_minute": round(statistics.median(first), 2) if first else None,
            "query_ms_last_minute": round(statistics.median(last), 2) if last else None,
        }
        if report["query_ms_first_minute"] and report["query_ms_last_minute"]:
            report["query_ms_drift"] = round(report["query_ms_last_minute"] - report["query_ms_first_minute"], 2)
        totals = [a[1] + a[3] + a[4] + a[5] for a in self.answers]
        report["stages_ms_median"] = self.stage_medians(self.answers)
        report["keyframe_ms_p99"] = round(sorted(totals)[int(0.99 * (len(totals) - 1))], 2)
        detector = sorted(a[1] + a[4] + a[5] for a in self.answers)
        report["detector_ms_p99"] = round(detector[int(0.99 * (len(detector) - 1))], 2)
        report["extraction_thread"] = bool(rospy.get_param("/mild_lcd/extraction_thread", True))
        report["drop_periods"] = self.drop_periods(start)
        return report

    @staticmethod
    def stage_medians(answers):
        names = ("query", "extract", "filter", "verify")
        columns = (1, 3, 4, 5)
        out = {name: round(statistics.median(a[c] for a in answers), 2) for name, c in zip(names, columns)}
        out["total"] = round(statistics.median(a[1] + a[3] + a[4] + a[5] for a in answers), 2)
        # The detector thread's own part (query with insertion, filter, verification): with
        # ~extraction_thread the next keyframe is extracted on another thread meanwhile, so this, not
        # the total, is what bounds the rate.
        out["detector"] = round(statistics.median(a[1] + a[4] + a[5] for a in answers), 2)
        return out

    def drop_periods(self, start):
        """Sampling periods whose dropped count rose, with the stage times of the keyframes answered
        in the 10 s before the period ended (a keyframe is answered well after it arrives when the
        queue is full, so these are the keyframes that were in the way)."""
        periods = []
        for before, now in zip(self.samples, self.samples[1:]):
            if now[4] <= before[4]:
                continue
            window = [a for a in self.answers if now[0] - 10 <= a[0] - start <= now[0]]
            periods.append({
                "at_s": round(now[0]),
                "dropped": now[4] - before[4],
                "database_keyframes": now[2],
                "keyframes_answered_per_s": round(len(window) / 10, 1),
                "stages_ms_median": self.stage_medians(window) if window else None,
            })
        return periods


def main():
    rospy.init_node("soak_monitor")
    monitor = Monitor()
    report = monitor.run()
    text = json.dumps(report, indent=1)
    print(text, flush=True)
    if monitor.report_path:
        with open(monitor.report_path, "w") as f:
            f.write(text + "\n")


if __name__ == "__main__":
    main()
