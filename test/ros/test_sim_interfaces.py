#!/usr/bin/python3
"""rostest of what a robotics user expects of tensegrity_sim (sim_interfaces.test): two nodes in /robot_a and
/robot_b, each with its own tf frames; effective parameters on the parameter server; live parameters through
dynamic_reconfigure; /diagnostics; pushes from outside; throttled warnings; the data topics' wall-rate cap.

Waits are bounds on behaviour that is missing, far above the time it takes."""
import math
import random
import threading
import time
import unittest

import dynamic_reconfigure.client
import rospy
import rostest
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from geometry_msgs.msg import Wrench
from rosgraph_msgs.msg import Log
from std_srvs.srv import SetBool, Trigger
from tf2_msgs.msg import TFMessage

from sim_test_util import wait_for
from active_tensegrity.msg import ActuationCommand, SimStatus, StrutArray, TargetWrench
from active_tensegrity.srv import ApplyWrench

A = "/robot_a/tensegrity_sim"
B = "/robot_b/tensegrity_sim"
STRUTS = ["S1", "S2", "S3"]
WAIT = 60.0


class Latest:
    """The latest message of a topic, and every one when asked."""

    def __init__(self, topic, cls, keep=False):
        self.lock = threading.Lock()
        self.msg = None
        self.all = []
        self.keep = keep
        self.sub = rospy.Subscriber(topic, cls, self.on)

    def on(self, msg):
        with self.lock:
            self.msg = msg
            if self.keep:
                self.all.append((time.monotonic(), msg))

    def get(self):
        with self.lock:
            return self.msg


def wrench(fx=0.0, fy=0.0, fz=0.0, tx=0.0, ty=0.0, tz=0.0):
    w = Wrench()
    w.force.x, w.force.y, w.force.z = fx, fy, fz
    w.torque.x, w.torque.y, w.torque.z = tx, ty, tz
    return w


def strut_z(struts, name):
    """The height (m) of a strut's centre in a StrutArray."""
    i = struts.names.index(name)
    return 0.5 * (struts.start[i].z + struts.end[i].z)


class SimInterfaces(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        rospy.init_node("test_sim_interfaces")
        for ns in (A, B):
            rospy.wait_for_service(ns + "/apply_wrench", timeout=WAIT)

    def test_01_each_robot_has_its_own_frames_with_one_publisher_each(self):
        publishers = {}  # child frame -> set of (publisher, parent)
        lock = threading.Lock()

        def on(msg):
            who = msg._connection_header["callerid"]
            with lock:
                for t in msg.transforms:
                    publishers.setdefault(t.child_frame_id, set()).add((who, t.header.frame_id))

        sub = rospy.Subscriber("/tf", TFMessage, on)
        expected = ["robot_a/" + s for s in STRUTS] + ["robot_b/" + s for s in STRUTS]
        try:
            self.assertTrue(wait_for(lambda: all(f in publishers for f in expected), WAIT), publishers)
            time.sleep(1.0)
        finally:
            sub.unregister()
        with lock:
            for s in STRUTS:
                self.assertEqual(publishers["robot_a/" + s], {(A, "world")})
                self.assertEqual(publishers["robot_b/" + s], {(B, "world_b")})
                self.assertNotIn(s, publishers)  # no frame without its prefix

    def test_02_every_effective_parameter_is_on_the_parameter_server(self):
        for name, value in (("real_time_factor", 1.0), ("publish_rate", 50.0), ("marker_rate", 30.0),
                            ("max_publish_wall_rate", 0.0), ("publish_clock", False), ("frame_id", "world"),
                            ("tf_prefix", "robot_a"), ("adaptive", True), ("start_paused", False),
                            ("contact_force_scale", 0.004), ("cable_tension_scale", 0.0), ("cable_width", 0.01),
                            ("strut_alpha", 0.7)):
            self.assertEqual(rospy.get_param(A + "/" + name), value, name)
        self.assertTrue(rospy.get_param(A + "/scene").endswith("config/scenes/prism.yaml"))
        # the command defaults come from the scene: the effective values, not 0
        self.assertGreater(rospy.get_param(A + "/default_speed"), 0.0)
        self.assertGreater(rospy.get_param(A + "/default_acceleration"), 0.0)
        self.assertEqual(rospy.get_param(B + "/frame_id"), "world_b")

    def test_03_live_parameters_change_and_a_bad_value_is_refused_by_name(self):
        status = Latest(A + "/status", SimStatus)
        client = dynamic_reconfigure.client.Client(A, timeout=WAIT)
        try:
            config = client.update_configuration({"real_time_factor": 3.0})
            self.assertEqual(config["real_time_factor"], 3.0)
            self.assertEqual(rospy.get_param(A + "/real_time_factor"), 3.0)
            # the measured factor follows (over windows of about a second)
            self.assertTrue(wait_for(lambda: status.get() and status.get().real_time_factor > 2.5, WAIT),
                            status.get())
            before = status.get().commands_rejected
            config = client.update_configuration({"publish_rate": -5.0, "strut_alpha": 0.5})
            self.assertEqual(config["publish_rate"], 50.0)  # refused: kept
            self.assertEqual(config["strut_alpha"], 0.5)  # the other change applied
            self.assertTrue(wait_for(lambda: status.get().commands_rejected == before + 1, WAIT))
            self.assertIn("~publish_rate must be > 0 Hz, got -5", status.get().last_rejection)
            config = client.update_configuration({"strut_alpha": 1.5})
            self.assertEqual(config["strut_alpha"], 0.5)
            self.assertIn("~strut_alpha must be in (0, 1], got 1.5", status.get().last_rejection)
        finally:
            client.update_configuration({"real_time_factor": 1.0, "strut_alpha": 0.7})
            client.close()
            status.sub.unregister()

    def test_04_diagnostics_report_health_and_rejected_commands(self):
        latest = {}  # status name -> the latest status of that name (both nodes publish /diagnostics)
        lock = threading.Lock()

        def on(msg):
            with lock:
                for st in msg.status:
                    latest[st.name] = st

        diag = rospy.Subscriber("/diagnostics", DiagnosticArray, on)

        def named(suffix):
            with lock:
                return latest.get(A.lstrip("/") + ": " + suffix)

        try:
            self.assertTrue(wait_for(lambda: named("simulation") and named("commands") and named("planner"), WAIT))
            sim = named("simulation")
            self.assertEqual(sim.hardware_id, "tensegrity_sim: prism")
            values = {kv.key: kv.value for kv in sim.values}
            for key in ("sim_time", "steps", "step_cuts", "real_time_factor", "requested_real_time_factor",
                        "solver_status", "active_contacts", "pushes"):
                self.assertIn(key, values)
            self.assertEqual(named("planner").level, DiagnosticStatus.OK)
            commands = {kv.key: kv.value for kv in named("commands").values}
            for key in ("accepted", "rejected", "last_rejection", "last_motion_simulated", "last_motion_wall",
                        "last_motion_real_time_factor"):
                self.assertIn(key, commands)
            # a bad command: the commands' status warns at the next report, naming it (after the reports of what
            # came before are OK)
            self.assertTrue(wait_for(lambda: named("commands").level == DiagnosticStatus.OK, WAIT))
            pub = rospy.Publisher(A + "/actuation", ActuationCommand, queue_size=10)
            self.assertTrue(wait_for(lambda: pub.get_num_connections() > 0, WAIT))
            pub.publish(ActuationCommand(names=["no_such_actuator"], targets=[0.1]))
            self.assertTrue(wait_for(lambda: named("commands").level == DiagnosticStatus.WARN, WAIT), named("commands"))
            self.assertIn("no_such_actuator", named("commands").message)
            # ... and is OK again at the report after
            self.assertTrue(wait_for(lambda: named("commands").level == DiagnosticStatus.OK, WAIT))
            # a motion of the actuator (1 cm at 0.1 m/s, paced at real time): its simulated and wall durations
            pub.publish(ActuationCommand(names=["lift"], targets=[0.01], max_speeds=[0.1]))

            def motion():
                values = {kv.key: kv.value for kv in named("commands").values}
                return float(values["last_motion_simulated"]), float(values["last_motion_wall"])

            self.assertTrue(wait_for(lambda: motion()[0] > 0.0, WAIT), named("commands"))
            simulated, wall = motion()
            self.assertGreater(simulated, 0.09)  # 0.1 s at the speed, more with the ramps
            self.assertGreater(wall, 0.0)
            # paused: said so
            rospy.ServiceProxy(A + "/pause", SetBool)(True)
            self.assertTrue(wait_for(lambda: named("simulation").message.startswith("paused"), WAIT),
                            named("simulation").message)
        finally:
            rospy.ServiceProxy(A + "/pause", SetBool)(False)
            diag.unregister()

    def test_05_a_push_moves_the_strut_and_bad_pushes_are_refused_by_name(self):
        apply = rospy.ServiceProxy(B + "/apply_wrench", ApplyWrench)
        clear = rospy.ServiceProxy(B + "/clear_wrenches", Trigger)
        struts = Latest(B + "/struts", StrutArray)
        status = Latest(B + "/status", SimStatus)
        try:
            for target, w, duration, words in (
                    ("nope", wrench(fz=-10), 1.0, "target 'nope' is no strut, point mass or node"),
                    ("", wrench(fz=-10), 1.0, "target is empty"),
                    ("S1", wrench(fx=float("nan")), 1.0, "wrench.force must be finite"),
                    ("S1", wrench(fz=-1e12), 1.0, "wrench.force must be at most 1e+09 N"),
                    ("S1", wrench(fz=-10), 0.0, "duration must be > 0 s"),
                    ("S1", wrench(fz=-10), float("inf"), "duration must be"),
                    ("S1", wrench(fz=-10), -2.0, "duration must be > 0 s"),
                    ("T1", wrench(tx=1.0), 1.0, "wrench.torque must be zero on node 'T1'")):
                r = apply(target, w, duration)
                self.assertFalse(r.success, target)
                self.assertIn(words, r.message)
                self.assertIn("nothing applied", r.message)
            self.assertTrue(wait_for(lambda: struts.get() is not None and status.get() is not None, WAIT))
            self.assertEqual(status.get().wrenches, 0)
            z0 = strut_z(struts.get(), "S1")
            # a torque along the strut is dropped, and the answer says so
            r = apply("S1", wrench(fz=-200.0), 2.0)
            self.assertTrue(r.success, r.message)
            self.assertTrue(wait_for(lambda: status.get().wrenches == 1, WAIT))
            self.assertTrue(wait_for(lambda: strut_z(struts.get(), "S1") < z0 - 0.01, WAIT))
            self.assertTrue(wait_for(lambda: status.get().wrenches == 0, WAIT))  # ends by itself
            # a standing load from the topic, removed by a zero wrench; ~clear_wrenches ends the rest
            pub = rospy.Publisher(B + "/wrench", TargetWrench, queue_size=10)
            self.assertTrue(wait_for(lambda: pub.get_num_connections() > 0, WAIT))
            pub.publish(TargetWrench(target="S2", wrench=wrench(fx=20.0)))
            self.assertTrue(wait_for(lambda: status.get().wrenches == 1, WAIT))
            pub.publish(TargetWrench(target="S2", wrench=wrench(fx=30.0)))  # replaces it
            time.sleep(0.5)
            self.assertEqual(status.get().wrenches, 1)
            pub.publish(TargetWrench(target="S2", wrench=wrench()))
            self.assertTrue(wait_for(lambda: status.get().wrenches == 0, WAIT))
            self.assertTrue(apply("S3", wrench(fy=5.0), -1.0).success)
            self.assertTrue(apply("T2", wrench(fz=5.0), -1.0).success)
            self.assertTrue(wait_for(lambda: status.get().wrenches == 2, WAIT))
            self.assertEqual(clear().message, "cleared 2 pushes")
            self.assertTrue(wait_for(lambda: status.get().wrenches == 0, WAIT))
            # random requests, the bad and the odd: each answered, the node running on, nothing non-finite
            rng = random.Random(7)
            values = [0.0, -0.0, 1.0, -1.0, 1e-300, 1e9, 1e9 + 1, -1e300, float("nan"), float("inf"), 5.5]
            targets = ["S1", "S2", "T1", "B1", "", "S1 ", "s1", "x" * 5000, "\u00e9", "T1/S1"]
            pub_w = rospy.Publisher(B + "/wrench", TargetWrench, queue_size=100)
            for k in range(60):
                w = wrench(*[rng.choice(values) for _ in range(6)])
                target = rng.choice(targets)
                if k % 2:
                    r = apply(target, w, rng.choice(values + [-1.0, 0.01]))
                    self.assertIn("nothing applied" if not r.success else "pushing", r.message)
                else:
                    pub_w.publish(TargetWrench(target=target, wrench=w))
            clear()
            self.assertTrue(wait_for(lambda: status.get().wrenches == 0, WAIT))
            # a push of 1e9 N may tear the prism apart: then the solver fails and says so (never NaN out), and a
            # reset brings it back
            time.sleep(0.5)
            for v in struts.get().axial_forces:
                self.assertTrue(math.isfinite(v))
            if status.get().solver_status != "running":
                self.assertNotEqual(status.get().message, "")
                rospy.ServiceProxy(B + "/reset", Trigger)()
            self.assertTrue(wait_for(lambda: status.get().solver_status == "running", WAIT), status.get())
            self.assertEqual(status.get().solver_status, "running")
            for v in struts.get().axial_forces:
                self.assertTrue(math.isfinite(v))
        finally:
            clear()
            struts.sub.unregister()
            status.sub.unregister()

    def test_06_rejected_commands_do_not_flood_the_log(self):
        lines = []
        lock = threading.Lock()

        def on(msg):
            if msg.name == A and msg.level == Log.WARN:
                with lock:
                    lines.append(msg.msg)

        sub = rospy.Subscriber("/rosout", Log, on)
        status = Latest(A + "/status", SimStatus)
        pub = rospy.Publisher(A + "/actuation", ActuationCommand, queue_size=200)
        try:
            self.assertTrue(wait_for(lambda: pub.get_num_connections() > 0 and status.get() is not None, WAIT))
            time.sleep(0.5)
            before = status.get().commands_rejected
            # 300 bad commands over about 3 s (the node's queue may drop some under load)
            start = time.monotonic()
            for k in range(300):
                pub.publish(ActuationCommand(names=["bad%d" % k], targets=[0.1]))
                time.sleep(0.01)
            self.assertTrue(wait_for(lambda: status.get().commands_rejected >= before + 100, WAIT),
                            status.get().commands_rejected - before)
            time.sleep(1.0)
            seconds = time.monotonic() - start
            with lock:
                n = len(lines)
            rejected = status.get().commands_rejected - before
            # a line per two wall seconds at most, each saying how many it stands for
            self.assertGreater(n, 0)
            self.assertLessEqual(n, 2 + seconds / 2.0, lines)
            self.assertTrue(any("more like it not logged" in line for line in lines), lines)
            print("[ measured ] %d rejected commands in %.1f s wrote %d warnings" % (rejected, seconds, n))
        finally:
            sub.unregister()
            status.sub.unregister()

    def test_07_the_wall_rate_cap_holds_the_data_topics_at_rtf_0(self):
        client = dynamic_reconfigure.client.Client(B, timeout=WAIT)
        struts = Latest(B + "/struts", StrutArray, keep=True)
        try:
            client.update_configuration({"real_time_factor": 0.0, "max_publish_wall_rate": 20.0})
            time.sleep(1.0)
            with struts.lock:
                struts.all.clear()
            time.sleep(3.0)
            with struts.lock:
                times = [t for t, _ in struts.all]
                stamps = [m.header.stamp.to_sec() for _, m in struts.all]
            self.assertGreater(len(times), 5)
            rate = (len(times) - 1) / (times[-1] - times[0])
            self.assertLess(rate, 1.5 * 20.0, rate)
            # simulated time runs on faster than the publications (real_time_factor 0)
            self.assertGreater(stamps[-1] - stamps[0], 0.0)
        finally:
            client.update_configuration({"real_time_factor": 1.0, "max_publish_wall_rate": 0.0})
            client.close()
            struts.sub.unregister()


if __name__ == "__main__":
    rostest.rosrun("active_tensegrity", "test_sim_interfaces", SimInterfaces)
