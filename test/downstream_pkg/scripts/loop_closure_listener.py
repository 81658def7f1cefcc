#!/usr/bin/python3
"""Acts on the loops mild_lcd accepts (docs/interface.md, "Consuming LoopClosure"). Subscribes to
loop_closure: remap it to the detector's (e.g. loop_closure:=/robot/loop_closure)."""
import rospy
from mild_lcd.msg import LoopClosure


def on_loop_closure(msg):
    for c in msg.candidates:
        if not c.accepted:  # verified, probability >= the decision (0.909): act on it
            continue
        rospy.loginfo("keyframe %d closes a loop with %d (p=%g, %d inliers)", msg.query_id, c.id, c.probability, c.inliers)
        if c.has_relative_pose:  # the candidate camera in the query camera's optical frame
            t = c.relative_translation
            rospy.loginfo("  translation %s %g %g %g", "in metres" if c.metric_translation else "direction", t.x, t.y, t.z)


if __name__ == "__main__":
    rospy.init_node("loop_closure_listener")
    rospy.Subscriber("loop_closure", LoopClosure, on_loop_closure, queue_size=100)
    rospy.spin()
