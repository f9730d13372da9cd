#!/usr/bin/python3
"""rostest of tensegrity_sim on the prism scene (sim_node.test): frames, topics, rate, services,
actuation ramps, trajectories, bad commands, bad scenes and parameters, solver failure.

The node publishes /clock (sim_node.test), so every stamp is the simulation's start plus simulated
time: rates, speeds and durations are checked in simulated time and hold however slowly the machine
runs. Waits are bounds on behaviour that is missing, far above the time it takes; wall-time figures
are only printed."""
import math
import os
import subprocess
import threading
import time
import unittest

import rospy
import rostest
from sensor_msgs.msg import JointState
from std_srvs.srv import SetBool, Trigger
from tf2_msgs.msg import TFMessage
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint
from visualization_msgs.msg import MarkerArray

from sim_test_util import wait_for
from active_tensegrity.msg import ActuationCommand, CableArray, ContactArray, SimStatus, StrutArray

NS = "/tensegrity_sim"
STRUTS = ["S1", "S2", "S3"]
CABLES = ["R1", "R2", "R3", "R4", "R5", "R6", "V1", "V2", "V3"]
RATE = 50.0  # the launch file's publish_rate (real time factor 1)
PERIOD = 1.0 / RATE  # s of simulated time between publications
MARKER_RATE = 2.0  # the launch file's marker_rate: ~markers at most this often per wall second
WAIT = 60.0  # s: bound on waiting for something that takes well under a second of wall time


def sim(stamp):
    """A header stamp as seconds (the simulation's start plus simulated time)."""
    return stamp.to_sec()


def finite(*values):
    return all(math.isfinite(v) for v in values)


class Recorder:
    """Keeps the latest message of every topic, counts them and records the actuator trace."""

    def __init__(self, ns):
        self.lock = threading.Lock()
        self.latest = {}
        self.counts = {}
        self.frames = set()
        self.trace = []  # (stamp, position, velocity) of the first actuator
        self.statuses = []  # every ~status message, in order
        self.cable_times = []  # (stamp in ns, monotonic wall time of arrival) of every ~cables message
        self.marker_times = []  # the same of every ~markers message
        self.nonfinite = []
        self.subs = [
            rospy.Subscriber(ns + "/contacts", ContactArray, self.on, "contacts"),
            rospy.Subscriber(ns + "/cables", CableArray, self.on, "cables"),
            rospy.Subscriber(ns + "/struts", StrutArray, self.on, "struts"),
            rospy.Subscriber(ns + "/actuators", JointState, self.on, "actuators"),
            rospy.Subscriber(ns + "/markers", MarkerArray, self.on, "markers"),
            rospy.Subscriber(ns + "/status", SimStatus, self.on, "status"),
        ]

    def on(self, msg, name):
        with self.lock:
            self.latest[name] = msg
            self.counts[name] = self.counts.get(name, 0) + 1
            if name == "status":
                self.statuses.append(msg)
            elif name == "markers":
                if msg.markers:
                    self.marker_times.append((msg.markers[0].header.stamp.to_nsec(), time.monotonic()))
            elif name == "actuators":
                self.trace.append((sim(msg.header.stamp), msg.position[0], msg.velocity[0]))
                if not finite(*msg.position, *msg.velocity, *msg.effort):
                    self.nonfinite.append(("actuators", msg))
            elif name == "cables":
                self.cable_times.append((msg.header.stamp.to_nsec(), time.monotonic()))
                for c in msg.cables:
                    if not finite(c.length, c.rest_length, c.tension):
                        self.nonfinite.append(("cables", c))
            elif name == "struts":
                if not finite(*msg.axial_forces):
                    self.nonfinite.append(("struts", msg))

    def get(self, name):
        with self.lock:
            return self.latest.get(name)

    def count(self, name):
        with self.lock:
            return self.counts.get(name, 0)

    def accepted_at(self, n):
        """Stamp of the first ~status that counts n accepted commands (the command's arrival), or None."""
        with self.lock:
            for st in self.statuses:
                if st.commands_accepted >= n:
                    return sim(st.header.stamp)
        return None


class TestSimNode(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        rospy.init_node("test_sim_node")
        cls.rec = Recorder(NS)
        cls.frames = set()
        cls.frames_lock = threading.Lock()
        cls.tf_sub = rospy.Subscriber("/tf", TFMessage, cls.on_tf)
        cls.actuation = rospy.Publisher(NS + "/actuation", ActuationCommand, queue_size=10)
        cls.trajectory = rospy.Publisher(NS + "/trajectory", JointTrajectory, queue_size=10)
        rospy.wait_for_service(NS + "/reset", timeout=WAIT)
        rospy.wait_for_service(NS + "/pause", timeout=WAIT)
        cls.reset = rospy.ServiceProxy(NS + "/reset", Trigger)
        cls.pause = rospy.ServiceProxy(NS + "/pause", SetBool)
        assert wait_for(lambda: cls.actuation.get_num_connections() > 0, WAIT)
        assert wait_for(lambda: cls.trajectory.get_num_connections() > 0, WAIT)

    @classmethod
    def on_tf(cls, msg):
        with cls.frames_lock:
            for t in msg.transforms:
                cls.frames.add((t.header.frame_id, t.child_frame_id))

    def position(self):
        return self.rec.get("actuators").position[0]

    def status(self):
        return self.rec.get("status")

    def now(self):
        """Stamp of the latest ~actuators message (the node's simulated time as last published)."""
        return sim(self.rec.get("actuators").header.stamp)

    def restart(self):
        """~reset, then waits for a ~status published after it that shows the simulated time back at 0."""
        with self.rec.lock:
            n = len(self.rec.statuses)
        res = self.reset()
        self.assertTrue(res.success, res.message)

        def restarted():
            with self.rec.lock:
                return any(st.sim_time < 0.5 for st in self.rec.statuses[n:])

        self.assertTrue(wait_for(restarted, WAIT))

    def settle(self):
        """Back to the scene's start, running."""
        self.pause(False)
        self.restart()
        self.assertTrue(wait_for(lambda: self.position() == 0.0, WAIT))

    def test_01_frames_topics_and_rate(self):
        self.assertTrue(wait_for(lambda: all(self.rec.get(n) is not None for n in
                                             ("contacts", "cables", "struts", "actuators", "markers", "status")),
                                 WAIT))
        self.assertTrue(wait_for(lambda: all(("world", s) in self.frames for s in STRUTS), WAIT), self.frames)
        cables = self.rec.get("cables")
        self.assertEqual([c.name for c in cables.cables], CABLES)
        self.assertTrue(all(c.tension > 0 and not c.slack for c in cables.cables))
        self.assertEqual(cables.header.frame_id, "world")
        # the prestressed prism's struts push: every axial force is a compression
        struts = self.rec.get("struts")
        self.assertEqual(list(struts.names), STRUTS)
        self.assertEqual(len(struts.axial_forces), len(STRUTS))
        self.assertTrue(all(f < 0 for f in struts.axial_forces), struts.axial_forces)
        act = self.rec.get("actuators")
        self.assertEqual(act.name, ["lift"])
        markers = self.rec.get("markers").markers
        struts = [m for m in markers if m.ns == "struts"]
        self.assertEqual(len(struts), 3)
        for m in struts:
            self.assertAlmostEqual(m.scale.x, 2 * 0.012)  # the real radius
            self.assertGreater(m.scale.z, 0.8)
        self.assertTrue(any(m.ns == "cables" and len(m.points) == 18 for m in markers))
        self.assertEqual(self.rec.get("contacts").contacts, [])  # contact is off in this scene
        # the rate: 50 Hz of simulated time. Paused first, so that the pacing's start is known: it restarts
        # when the node sees the resume, after the call below began
        self.assertTrue(self.pause(True).success)
        self.assertTrue(wait_for(lambda: self.status().paused, WAIT))
        resumed_at = self.status().header.stamp.to_nsec()  # the simulated time, frozen while paused
        wall0 = time.monotonic()
        self.assertTrue(self.pause(False).success)
        span = 3.0  # s of simulated time

        def after(times=None):
            with self.rec.lock:
                return [(1e-9 * (ns - resumed_at), arrived) for ns, arrived in
                        (self.rec.cable_times if times is None else times)
                        if ns - resumed_at > 0.5e9 * PERIOD]

        self.assertTrue(wait_for(lambda: len(after()) > 1 and after()[-1][0] - after()[0][0] >= span, 30 * span))
        got = after()  # (simulated time since the resume, wall time of arrival)
        stamps = [t for t, _ in got]
        gaps = [b - a for a, b in zip(stamps, stamps[1:])]
        # every publication on the grid of 1/RATE of simulated time: each gap a whole number (>= 1) of
        # periods (a gap of several is a message lost in transport, which the count below bounds)
        for g in gaps:
            self.assertGreaterEqual(round(g / PERIOD), 1, gaps)
            self.assertAlmostEqual(g, round(g / PERIOD) * PERIOD, delta=1e-6)
        # messages per simulated second: RATE at most (none between grid points), 0.7 RATE at least
        per_sim_second = (len(stamps) - 1) / (stamps[-1] - stamps[0])
        self.assertLessEqual(per_sim_second, RATE * (1 + 1e-6))
        self.assertGreaterEqual(per_sim_second, 0.7 * RATE)
        # paced at real_time_factor 1: never ahead of real time since the resume. Simulated time t (since
        # the resume) is published only once the wall clock has passed pacing start + t, and the pacing
        # started after wall0; a slow machine only falls behind, which this does not check
        for t, arrived in got:
            self.assertLessEqual(t, arrived - wall0 + 1e-6)
        st = self.status()
        self.assertEqual(st.solver_status, "running")
        wall = got[-1][1] - got[0][1]
        # ~markers: with published states (on the same grid), at most MARKER_RATE per wall second. The node
        # sends them at least 1 / MARKER_RATE apart, so n of them arrive over at least (n - 1) / MARKER_RATE s
        # less the first one's transport delay (allowed 1 s here). Sent with every publication they would be
        # 50 per wall second: 150 over these 3 s against at most 8
        marks = after(self.rec.marker_times)
        self.assertGreater(len(marks), 1)
        for t, _ in marks:
            self.assertAlmostEqual(t, round(t / PERIOD) * PERIOD, delta=1e-6)
        marks_wall = marks[-1][1] - marks[0][1]
        self.assertLessEqual(len(marks) - 1, MARKER_RATE * (marks_wall + 1.0), (len(marks), marks_wall))
        print("[ measured ] ~cables: %.1f per simulated second, %.1f per wall second; ~markers %.1f per wall "
              "second; real-time factor %.2f (~status)"
              % (per_sim_second, (len(got) - 1) / wall if wall > 0 else float("nan"),
                 (len(marks) - 1) / marks_wall if marks_wall > 0 else float("nan"), st.real_time_factor))

    def test_02_actuation_ramps_at_the_set_speed(self):
        self.settle()
        accepted = self.status().commands_accepted
        with self.rec.lock:
            self.rec.trace = []
        self.actuation.publish(ActuationCommand(names=["lift"], targets=[0.03], max_speeds=[0.01],
                                                max_accelerations=[0.1]))
        # 0.03 m at 0.01 m/s with 0.1 m/s^2: 3.1 s of simulated time
        self.assertTrue(wait_for(lambda: abs(self.position() - 0.03) < 1e-12, WAIT), self.position())
        self.assertEqual(self.status().commands_accepted, accepted + 1)
        start = self.rec.accepted_at(accepted + 1)
        self.assertIsNotNone(start)
        with self.rec.lock:
            trace = list(self.rec.trace)
        velocities = [v for _, _, v in trace]
        self.assertLessEqual(max(velocities), 0.01 + 1e-12)
        self.assertGreater(max(velocities), 0.01 - 1e-12)  # cruises at the limit
        positions = [p for _, p, _ in trace]
        self.assertTrue(all(b >= a - 1e-15 for a, b in zip(positions, positions[1:])))  # monotone
        moving = [(t, p) for t, p, _ in trace if 0.005 < p < 0.025]
        speed = (moving[-1][1] - moving[0][1]) / (moving[-1][0] - moving[0][0])
        self.assertAlmostEqual(speed, 0.01, delta=1e-5)  # in simulated time (stamps), cruising
        # arrived when the ramp ends, 3.1 s after the command (first published at the next grid point)
        arrived = next(t for t, p, _ in trace if abs(p - 0.03) < 1e-12)
        self.assertGreaterEqual(arrived - start, 3.1 - 1e-5)
        self.assertLessEqual(arrived - start, 3.1 + PERIOD + 1e-6)

    def test_03_trajectory_is_followed(self):
        self.settle()
        accepted = self.status().commands_accepted
        self.actuation.publish(ActuationCommand(names=["lift"], targets=[0.03]))
        self.assertTrue(wait_for(lambda: abs(self.position() - 0.03) < 1e-12, WAIT))
        self.assertTrue(wait_for(lambda: self.status().commands_accepted == accepted + 1, WAIT))
        accepted += 1
        with self.rec.lock:
            self.rec.trace = []
        traj = JointTrajectory(joint_names=["lift"])
        traj.points = [JointTrajectoryPoint(positions=[0.01], time_from_start=rospy.Duration(1.0)),
                       JointTrajectoryPoint(positions=[0.04], time_from_start=rospy.Duration(2.0))]
        self.trajectory.publish(traj)
        self.assertTrue(wait_for(lambda: abs(self.position() - 0.04) < 1e-12, WAIT))
        start = self.rec.accepted_at(accepted + 1)  # the trajectory's time 0 (its arrival, simulated time)
        self.assertIsNotNone(start)
        with self.rec.lock:
            trace = list(self.rec.trace)
        # monotone cubic: the lowest point is the first point, reached at its time (simulated time,
        # between the two samples around it)
        t_min, p_min, _ = min(trace, key=lambda x: x[1])
        self.assertAlmostEqual(p_min, 0.01, delta=2e-4)  # sampled at 50 Hz around a flat minimum
        self.assertAlmostEqual(t_min - start, 1.0, delta=PERIOD + 1e-6)
        self.assertTrue(all(0.01 - 1e-9 <= p <= 0.04 + 1e-9 for _, p, _ in trace))
        # the last point reached at its time
        arrived = next(t for t, p, _ in trace if abs(p - 0.04) < 1e-12)
        self.assertGreaterEqual(arrived - start, 2.0 - 1e-5)
        self.assertLessEqual(arrived - start, 2.0 + PERIOD + 1e-6)

    def test_04_bad_commands_are_rejected_and_nothing_breaks(self):
        self.settle()
        self.actuation.publish(ActuationCommand(names=["lift"], targets=[0.02]))
        self.assertTrue(wait_for(lambda: abs(self.position() - 0.02) < 1e-12, WAIT))
        nan, inf = float("nan"), float("inf")

        def traj(names, points):
            t = JointTrajectory(joint_names=names)
            t.points = [JointTrajectoryPoint(positions=p, time_from_start=rospy.Duration(s)) for s, p in points]
            return t

        bad = [
            (self.actuation, ActuationCommand(names=["nope"], targets=[0.01]), "unknown actuator 'nope'"),
            (self.actuation, ActuationCommand(names=["lift"], targets=[nan]), "target of 'lift' is nan: not a finite number"),
            (self.actuation, ActuationCommand(names=["lift"], targets=[inf]), "target of 'lift' is inf"),
            (self.actuation, ActuationCommand(names=["lift"], targets=[0.2]), "outside its range [0, 0.05]"),
            (self.actuation, ActuationCommand(names=["lift"], targets=[-0.01]), "outside its range"),
            (self.actuation, ActuationCommand(names=["lift"], targets=[0.01], max_speeds=[-1.0]),
             "max_speeds of 'lift' is -1"),
            (self.actuation, ActuationCommand(names=["lift"], targets=[0.01], max_speeds=[0.0]),
             "max_speeds of 'lift' is 0"),
            (self.actuation, ActuationCommand(names=["lift"], targets=[0.01, 0.02]), "2 targets for 1"),
            (self.actuation, ActuationCommand(names=[], targets=[]), "no actuator names"),
            (self.trajectory, traj(["lift"], [(1.0, [0.01]), (0.5, [0.02])]), "strictly increasing"),
            (self.trajectory, traj(["nope"], [(1.0, [0.01])]), "unknown actuator 'nope'"),
            (self.trajectory, traj(["lift"], [(1.0, [nan])]), "position of 'lift' is nan"),
            (self.trajectory, traj(["lift"], [(1.0, [0.5])]), "outside its range"),
            (self.trajectory, traj(["lift"], []), "no points"),
            # a 1 MB name reaches the latched status (re-sent every second) and the log only cut
            (self.actuation, ActuationCommand(names=["n" * 1000000], targets=[0.01]), "(1000000 bytes)"),
        ]
        for pub, msg, reason in bad:
            before = self.status().commands_rejected
            pub.publish(msg)
            self.assertTrue(wait_for(lambda: self.status().commands_rejected == before + 1, WAIT), reason)
            self.assertIn(reason, self.status().last_rejection)
            self.assertLess(len(self.status().last_rejection), 1000)
        # nothing applied (after another 0.5 s of simulated time), still running and publishing finite numbers
        last = sim(self.status().header.stamp)
        self.assertTrue(wait_for(lambda: self.now() >= last + 0.5, WAIT))
        self.assertAlmostEqual(self.position(), 0.02, delta=1e-12)
        st = self.status()
        self.assertEqual(st.solver_status, "running")
        self.assertFalse(st.paused)
        n0 = self.rec.count("cables")
        self.assertTrue(wait_for(lambda: self.rec.count("cables") > n0 + 10, WAIT))
        self.assertEqual(self.rec.nonfinite, [])

    def test_05_pause_and_reset(self):
        self.settle()
        self.actuation.publish(ActuationCommand(names=["lift"], targets=[0.01]))
        self.assertTrue(wait_for(lambda: self.status().sim_time >= 0.5, WAIT))
        res = self.pause(True)
        self.assertTrue(res.success)
        self.assertTrue(wait_for(lambda: self.status().paused, WAIT))
        t0 = self.status().sim_time

        # rviz shows where the simulation stopped: the last ~markers are of the last published state, also
        # when its publication went without them (~marker_rate)
        def stamps():
            with self.rec.lock:
                return (self.rec.latest["markers"].markers[0].header.stamp,
                        self.rec.latest["cables"].header.stamp)

        self.assertTrue(wait_for(lambda: stamps()[0] == stamps()[1], WAIT), stamps())
        time.sleep(0.5)  # no stepping while paused
        self.assertEqual(self.status().sim_time, t0)
        self.assertEqual(self.status().solver_status, "paused")
        self.assertTrue(self.pause(False).success)
        # runs on from t0
        self.assertTrue(wait_for(lambda: self.status().sim_time > max(t0 + 0.2, 1.0), WAIT))
        self.restart()
        self.assertTrue(wait_for(lambda: self.position() == 0.0, WAIT))

    def test_06_solver_failure_pauses_at_the_last_good_state(self):
        rec = Recorder("/failing_sim")
        self.assertTrue(wait_for(lambda: rec.get("status") is not None and rec.get("status").paused, WAIT))
        st = rec.get("status")
        self.assertEqual(st.solver_status, "max_iterations")
        self.assertIn("did not converge", st.message)
        t0 = st.sim_time
        time.sleep(0.5)
        self.assertEqual(rec.get("status").sim_time, t0)
        resume = rospy.ServiceProxy("/failing_sim/pause", SetBool)(False)
        self.assertFalse(resume.success)
        self.assertIn("reset", resume.message)
        self.assertEqual(rec.nonfinite, [])

    def test_07_bad_scene_or_parameter_exits_with_code_1(self):
        cases = [
            (["_scene:=/no/such/scene.yaml"], "/no/such/scene.yaml"),
            (["_scene:=package://no_such_package/x.yaml"], "no_such_package"),
            (["_publish_rate:=-5.0"], "~publish_rate must be > 0"),
            (["_marker_rate:=-1"], "~marker_rate must be >= 0 Hz of wall time (0 = with every publication), got -1"),
            (["_real_time_factor:=fast"], "~real_time_factor must be a number"),
            (["_queue_size:=0"], "~queue_size must be a whole number of messages from 1 to 100000, got 0"),
            (["_queue_size:=2.5"], "~queue_size must be a whole number of messages from 1 to 100000, got 2.5"),
            (["_scene:=package://active_tensegrity/config/scenes/prism.yaml", "_overrides:={solver.dt: -1}"],
             "dt"),
        ]
        for i, (args, expect) in enumerate(cases):
            proc = subprocess.run(["rosrun", "active_tensegrity", "tensegrity_sim", "__name:=bad_%d" % i] + args,
                                  stdout=subprocess.PIPE, stderr=subprocess.STDOUT, timeout=2 * WAIT,
                                  env=dict(os.environ), universal_newlines=True)
            self.assertEqual(proc.returncode, 1, proc.stdout)
            self.assertIn(expect, proc.stdout)


if __name__ == "__main__":
    rostest.rosrun("active_tensegrity", "sim_node", TestSimNode)
