#!/usr/bin/python3
"""rostest of tensegrity_height_controller on the tower (sim_control.test, docs/control.md).

The sim publishes /clock and every time here is simulated time: the stamps of ~struts, from which the test
computes the top height itself (the largest z of the strut ends). Bounds in simulated time, tolerances with
margin over the measured behaviour (docs/control.md); wall-time waits are bounds on behaviour that is
missing, far above what it takes. The tests run in order and build on each other (one tower)."""
import math
import subprocess
import threading
import unittest

import rospy
import rostest
from geometry_msgs.msg import Vector3, Wrench
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64, Float64MultiArray
from std_srvs.srv import SetBool

from sim_test_util import wait_for
from active_tensegrity.msg import StrutArray
from active_tensegrity.srv import ApplyWrench

NS = "/tensegrity_sim"
CTRL = "/tensegrity_height_controller"
SETPOINT = 1.0  # m, control.launch's default
TOL = 0.05  # m: "at the setpoint" (measured: within 1-2 cm once settled, 5 cm at most in the push's wake)
HOLD = 2.0  # s: how long the height must stay within TOL to count as settled
TOP = ["T1", "T2", "T3", "T4"]
PUSH = -50.0  # N per top node, down: 200 N in all (measured: 15 cm down, back within 2 cm in 8 s)
PUSH_TIME = 20.0  # s of simulated time
WALL = 600.0  # s: bound on a wait of tens of simulated seconds at twice real time


class History:
    """(stamp, height) of every ~struts message and (stamp, rate of pull1) of every ~actuators message."""

    def __init__(self):
        self.lock = threading.Lock()
        self.heights = []
        self.pulls = []
        rospy.Subscriber(NS + "/struts", StrutArray, self.on_struts, queue_size=100)
        rospy.Subscriber(NS + "/actuators", JointState, self.on_actuators, queue_size=100)

    def on_struts(self, msg):
        h = max([p.z for p in msg.start] + [p.z for p in msg.end])
        with self.lock:
            self.heights.append((msg.header.stamp.to_sec(), h))

    def on_actuators(self, msg):
        with self.lock:
            i = msg.name.index("pull1")
            self.pulls.append((msg.header.stamp.to_sec(), msg.velocity[i]))

    def now(self):
        with self.lock:
            return self.heights[-1][0] if self.heights else None

    def since(self, t0, which="heights"):
        with self.lock:
            return [(t, v) for t, v in getattr(self, which) if t >= t0]


def first_hold(samples, low, high, hold):
    """The stamp from which the samples stay within [low, high] for `hold` s (None when they never do)."""
    start = None
    for t, h in samples:
        if low <= h <= high:
            if start is None:
                start = t
            if t - start >= hold:
                return start
        else:
            start = None
    return None


class TestSimControl(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        rospy.init_node("test_sim_control")
        cls.history = History()
        cls.state = None
        cls.state_lock = threading.Lock()
        rospy.Subscriber(CTRL + "/state", Float64MultiArray, cls.on_state, queue_size=100)
        cls.states = []
        cls.setpoint = rospy.Publisher(CTRL + "/setpoint", Float64, queue_size=10)
        assert wait_for(lambda: cls.history.now() is not None and cls.setpoint.get_num_connections() > 0, 60)
        rospy.wait_for_service(NS + "/apply_wrench", 60)
        rospy.wait_for_service(CTRL + "/enable", 60)
        cls.apply = rospy.ServiceProxy(NS + "/apply_wrench", ApplyWrench)
        cls.enable = rospy.ServiceProxy(CTRL + "/enable", SetBool)

    @classmethod
    def on_state(cls, msg):
        with cls.state_lock:
            cls.states.append(tuple(msg.data))

    def wait_sim(self, until):
        """Waits until the simulated time reaches `until` (s)."""
        self.assertTrue(wait_for(lambda: self.history.now() >= until, WALL), "the simulation stopped")

    def settle(self, bound, low=SETPOINT - TOL, high=SETPOINT + TOL):
        """Waits at most `bound` s of simulated time for the height to stay in [low, high] for HOLD s; returns
        the stamp it entered for good."""
        t0 = self.history.now()
        found = [None]

        def settled():
            found[0] = first_hold(self.history.since(t0), low, high, HOLD)
            return found[0] is not None or self.history.now() > t0 + bound + HOLD

        self.assertTrue(wait_for(settled, WALL), "the simulation stopped")
        return found[0], t0

    def push(self, force, duration):
        for node in TOP:
            res = self.apply(target=node, wrench=Wrench(force=Vector3(0.0, 0.0, force)), duration=duration)
            self.assertTrue(res.success, res.message)

    def test_1_settles_at_the_setpoint(self):
        # from the rest height (2 m) the tower is folded to 1.0 m; measured: within 5 cm for good after 4-8 s
        start, t0 = self.settle(30.0)
        self.assertIsNotNone(start, "the height did not settle within %g m of %g m in 30 s" % (TOL, SETPOINT))
        rospy.loginfo("settled within %g m after %.2f s", TOL, start - t0)
        with self.state_lock:
            last = self.states[-1]
        self.assertTrue(all(math.isfinite(v) for v in last), last)
        self.assertAlmostEqual(last[2], SETPOINT)

    def test_2_push_is_taken_out_while_it_acts_and_after(self):
        self.assertIsNotNone(self.settle(30.0)[0])
        t_push = self.history.now()
        self.push(PUSH, PUSH_TIME)
        t_end = t_push + PUSH_TIME
        # the push acts: the top goes down (measured: 15 cm)
        self.wait_sim(t_push + 3.0)
        lowest = min(h for _, h in self.history.since(t_push))
        self.assertLess(lowest, SETPOINT - TOL, "the push did not move the top (lowest %.3f m)" % lowest)
        # while it acts, the integral term brings the height back: measured 7.5-10.7 s; bound 16 s
        self.wait_sim(t_end - 0.5)
        back = first_hold(self.history.since(t_push), SETPOINT - TOL, SETPOINT + TOL, HOLD)
        self.assertIsNotNone(back, "not back within %g m during the push" % TOL)
        self.assertLess(back - t_push, 16.0, "back within %g m only %.2f s into the push" % (TOL, back - t_push))
        with self.state_lock:
            held = [s for s in self.states if t_end - 2.0 <= s[0] <= t_end - 0.5]
        # the pulls were let out to carry the push (measured: 0.56 -> 0.35 m)
        self.assertTrue(held)
        rospy.loginfo("push: lowest %.3f m, back within %g m after %.2f s, command %.3f m", lowest, TOL,
                      back - t_push, held[-1][4])
        # after it ends the tower springs up (measured: +34 cm) and is brought back: bound 25 s
        self.wait_sim(t_end + 0.05)
        start, _ = self.settle(25.0)
        self.assertIsNotNone(start, "not back within %g m in 25 s after the push ended" % TOL)
        highest = max(h for t, h in self.history.since(t_end) if t <= start)
        rospy.loginfo("after the push: highest %.3f m, back within %g m after %.2f s", highest, TOL, start - t_end)

    def test_3_latency_of_a_setpoint_step(self):
        settled, _ = self.settle(30.0)
        self.assertIsNotNone(settled)
        # what the settled loop does by itself: the ranges of pull1's rate and of the height over the last HOLD s
        t_now = self.history.now()
        pulls = [u for _, u in self.history.since(t_now - HOLD, "pulls")]
        heights = [h for _, h in self.history.since(t_now - HOLD)]
        with self.state_lock:
            n = len(self.states)
        step = SETPOINT - 0.1
        self.setpoint.publish(Float64(step))
        try:
            # the command: the first controller cycle on the new setpoint (its state's stamp)
            self.assertTrue(wait_for(lambda: any(abs(s[2] - step) < 1e-12 for s in self.states[n:]), WALL))
            with self.state_lock:
                t_cmd = next(s for s in self.states[n:] if abs(s[2] - step) < 1e-12)[0]
            self.wait_sim(t_cmd + 5.0)
            # the effect: what the settled loop did not do by itself: pull1 pulling in 5 cm/s faster than it did
            # before the step, the height 5 mm below its range
            t_act = next((t for t, v in self.history.since(t_cmd, "pulls") if v > max(pulls) + 0.05), None)
            t_h = next((t for t, h in self.history.since(t_cmd) if h < min(heights) - 5e-3), None)
            self.assertIsNotNone(t_h, "the height did not move in 5 s")
            rospy.loginfo("latency: command -> pulls %s, command -> height %.3f s",
                          "%.3f s" % (t_act - t_cmd) if t_act is not None else "not told from the loop's own motion",
                          t_h - t_cmd)
            # measured (twice real time): 0.5-1.7 s to the height (the tower's slow folding mode); the bound has
            # margin for a loaded machine. The pulls' start is reported, not bounded: the settled loop moves them too
            self.assertLess(t_h - t_cmd, 3.0)
            start, _ = self.settle(20.0, step - TOL, step + TOL)
            self.assertIsNotNone(start, "not within %g m of %g m in 20 s" % (TOL, step))
        finally:
            self.setpoint.publish(Float64(SETPOINT))
        self.assertIsNotNone(self.settle(30.0)[0])

    def test_4_without_integral_the_push_leaves_an_offset(self):
        self.assertIsNotNone(self.settle(30.0)[0])
        self.assertTrue(self.enable(False).success)
        p_only = subprocess.Popen(["rosrun", "active_tensegrity", "tensegrity_height_controller",
                                   "__name:=p_only_controller", "_ki:=0.0"],
                                  stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        try:
            # the P-only controller starts from where the pulls are (bumpless): wait for its state
            got = []
            sub = rospy.Subscriber("/p_only_controller/state", Float64MultiArray, lambda m: got.append(m.data))
            self.assertTrue(wait_for(lambda: len(got) > 10, 120), "the P-only controller does not run")
            t_push = self.history.now()
            self.push(PUSH, PUSH_TIME)
            self.wait_sim(t_push + PUSH_TIME - 0.5)
            late = [h for t, h in self.history.since(t_push + PUSH_TIME - 4.0) if t < t_push + PUSH_TIME - 0.5]
            mean = sum(late) / len(late)
            rospy.loginfo("P-only: mean height over the push's last 3.5 s %.3f m", mean)
            # the proportional term alone lets the pulls out by kp * error: an offset remains (measured >= 10 cm)
            self.assertLess(mean, SETPOINT - TOL, "no offset without the integral term (%.3f m)" % mean)
            sub.unregister()
        finally:
            p_only.terminate()
            p_only.wait(timeout=60)
        self.assertTrue(self.enable(True).success)
        self.assertIsNotNone(self.settle(40.0)[0], "the PI controller did not take the tower back")

    def test_5_bad_parameters_stop_the_controller(self):
        cases = [("_kp", "-1", "-1"), ("_ki", ".nan", "nan"), ("_rate", "0", "0"), ("_max_command", "-1", "-1")]
        for i, (param, value, shown) in enumerate(cases):
            # a node name of its own each time: private parameters stay on the parameter server
            bad = subprocess.run(["rosrun", "active_tensegrity", "tensegrity_height_controller",
                                  "__name:=bad_controller_%d" % i, "%s:=%s" % (param, value)],
                                 stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, timeout=120)
            self.assertEqual(bad.returncode, 1, (param, bad.stderr))
            name = "~" + param[1:]
            self.assertIn(name, bad.stderr)
            self.assertIn(shown, bad.stderr.split(name, 1)[1])


if __name__ == "__main__":
    rostest.rosrun("active_tensegrity", "sim_control", TestSimControl)
