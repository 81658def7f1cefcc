#!/usr/bin/python3
"""Records mild_lcd's loop closures, and the team's status, as JSON lines for check_team.py.

ROS node (run by /usr/bin/python3: Debian's rospy). test/team/three_hosts.sh runs one on each host
whose view it needs: a recorder sees a message only while its host can reach the publisher's, so
the checker gets one file per recorder and tells a double report (twice in one file) from the same
message seen by two recorders.

  record_loops.py --out FILE --label NAME --robots "robot1 robot2" [--status TOPIC] [--ready FILE]
                  [--latest-status FILE] [--connections FILE]

Every line is one message, stamped with the wall-clock time it arrived ("received", seconds since
the epoch, the clock three_hosts.sh writes its schedule in):
  {"kind": "loop", "topic": "/robot1/loop_closure", "query_station": "", "query_robot": "robot1",
   "query_id": 7, "query_session": 0, "stamp": 0.7, "candidates": [{"station": "", "robot": "robot1",
   "id": 3, "session": 0, "probability": 0.2, "accepted": false, "verified": false}, ...], ...}
  {"kind": "status", "topic": "/mild_team/status", "type": "pkg/Type", "fields": {...}, ...}
Messages are decoded with the definition their publisher sends (as rosbag does), not with this
package's generated Python classes: the recorder then takes whatever the running node publishes,
also from a build whose Python messages lag its C++ ones, and needs no change when the status
message changes. Fields a message lacks are recorded as "" (the station fields of a node of
before the team link, or of the single-node reference run).
--ready is written once every loop_closure topic has a publisher connected, so that the harness
plays no keyframe whose answer could reach this recorder before it listens.
--latest-status holds the last status of each station, with its arrival time, as one JSON object
  {"alpha": {"received": 1796537079.27, "fields": {...}}, ...}, replaced (rename) at each status, so
  that the harness can copy what every station said last before it stops one.
--connections holds, per loop_closure topic, the publishers this recorder is connected to (their
  XML-RPC URIs), replaced whenever they change: a restarted station is a new URI, so the harness
  knows when this recorder listens to it again.
"""
import argparse
import json
import os
import threading
import time

import genpy
import genpy.dynamic
import rospy


def plain(value):
    """A ROS message (or field) as JSON-ready data; byte arrays as their length (only sizes matter here)."""
    if isinstance(value, genpy.TVal):  # Time and Duration
        return value.to_sec()
    if isinstance(value, genpy.Message):
        return {name: plain(getattr(value, name)) for name in value.__slots__}
    if isinstance(value, (bytes, bytearray)):
        return len(value)
    if isinstance(value, (list, tuple)):
        return [plain(v) for v in value]
    return value


class Recorder:
    def __init__(self, args):
        self.label = args.label
        self.out = open(args.out, "a", encoding="utf-8")
        self.lock = threading.Lock()  # rospy calls back from one thread per connection
        self.classes = {}  # (type, md5sum) -> the class generated from the publisher's definition
        self.latest_path = args.latest_status
        self.latest = {}  # station -> {"received": t, "fields": {...}}
        self.loop_subscribers = [
            rospy.Subscriber(f"/{robot}/loop_closure", rospy.AnyMsg, self.on_loop_closure,
                             callback_args=f"/{robot}/loop_closure", queue_size=1000)
            for robot in args.robots.split()
        ]
        if args.status:
            rospy.Subscriber(args.status, rospy.AnyMsg, self.on_status, callback_args=args.status, queue_size=100)

    def decode(self, raw):
        header = raw._connection_header
        key = (header["type"], header["md5sum"])
        with self.lock:
            if key not in self.classes:
                self.classes[key] = genpy.dynamic.generate_dynamic(header["type"], header["message_definition"])[
                    header["type"]]
        return self.classes[key]().deserialize(raw._buff)

    def write(self, record):
        record["recorder"] = self.label
        record["received"] = time.time()
        line = json.dumps(record, sort_keys=True)
        with self.lock:
            self.out.write(line + "\n")
            self.out.flush()  # the harness polls the file to see when the stations are idle
        return record

    def on_loop_closure(self, raw, topic):
        msg = self.decode(raw)
        self.write({
            "kind": "loop",
            "topic": topic,
            "query_station": getattr(msg, "query_station", ""),
            "query_robot": msg.query_robot,
            "query_id": msg.query_id,
            "query_session": msg.query_session,
            "stamp": msg.header.stamp.to_sec(),
            "database_size": msg.database_size,
            "candidates": [{
                "station": getattr(c, "station", ""),
                "robot": c.robot,
                "id": c.id,
                "session": c.session,
                "probability": c.probability,
                "accepted": c.accepted,
                "verified": c.verified,
            } for c in msg.candidates],
        })

    def on_status(self, raw, topic):
        record = self.write({"kind": "status", "topic": topic, "type": raw._connection_header["type"],
                             "fields": plain(self.decode(raw))})
        if self.latest_path:
            station = record["fields"].get("station", "")
            with self.lock:
                self.latest[station] = {"received": record["received"], "fields": record["fields"]}
                write_json(self.latest_path, self.latest)

    def connections(self):
        """topic -> the URIs of the publishers connected (sorted)."""
        return {s.resolved_name: sorted(c[1] for c in s.impl.get_stats_info()) for s in self.loop_subscribers}

    def connected(self):
        return all(s.get_num_connections() > 0 for s in self.loop_subscribers)


def write_json(path, data):
    """Replaced whole (a reader never sees half of it)."""
    with open(path + ".tmp", "w", encoding="utf-8") as f:
        json.dump(data, f, sort_keys=True)
    os.replace(path + ".tmp", path)


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--out", required=True, help="JSON lines file (appended to)")
    parser.add_argument("--label", required=True, help="names this recorder in every record")
    parser.add_argument("--robots", required=True, help="robots whose /ROBOT/loop_closure to record")
    parser.add_argument("--status", default="", help="also record this topic (any type)")
    parser.add_argument("--ready", default="", help="file to create once every loop_closure topic is connected")
    parser.add_argument("--latest-status", default="", help="file holding each station's last status (with --status)")
    parser.add_argument("--connections", default="", help="file holding the publishers connected, per topic")
    args = parser.parse_args(rospy.myargv()[1:])
    rospy.init_node("mild_team_recorder", anonymous=True)  # anonymous: one per host, same master
    recorder = Recorder(args)
    ready = not args.ready
    connections = None
    while not rospy.is_shutdown():
        if not ready and recorder.connected():
            with open(args.ready + ".tmp", "w", encoding="utf-8") as f:
                f.write(f"{time.time()}\n")
            os.replace(args.ready + ".tmp", args.ready)
            ready = True
        if args.connections and recorder.connections() != connections:
            connections = recorder.connections()
            write_json(args.connections, connections)
        time.sleep(0.1)  # wall time: rospy.sleep would follow /clock if someone published it


if __name__ == "__main__":
    main()
