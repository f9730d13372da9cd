#!/usr/bin/python3
"""rostest of tensegrity_sim's ~plan_folding from a moving tower (sim_plan_moving.test): what executes is what was
verified.

Three starts, each after a ~reset: the cables pulled in at 0.3 m/s and the node paused 2.5 s into the pull (struts
and actuators moving); a plan requested while the cables are pulled in at 0.1 m/s, without a pause; and the tower
ringing 0.4 s after a fast pull has stopped. Each plan asks for execution; the contact forces the node then
publishes must stay under the verified peak. The node steps adaptively (its default), the verification at the
scene's fixed dt, and ~contacts samples the motion at 50 Hz of simulated time: the published peak may lie below the
verified one, and above it by the two integrators' difference in a peak of contact force (docs/ros.md, "Time
stepping": 11.7 and 7.9 % from a fine reference; the ringing start has shown 883 N published against 800 N
verified), so the check allows 25 % + 5 N. Planned and verified from rest, the first and third starts gave 176.5
and 171.5 N verified, 818-823 and 650-751 N published; the second was not executed (the actuators had moved on
while it was planned).

The node publishes /clock: waits are in simulated time (stamps), with wall-time bounds far above what they take, so
the outcome does not depend on the machine's speed."""
import threading
import time
import unittest

import rospy
import rostest
from sensor_msgs.msg import JointState
from std_srvs.srv import SetBool, Trigger

from sim_test_util import wait_for
from active_tensegrity.msg import ActuationCommand, ContactArray
from active_tensegrity.srv import PlanFolding, PlanFoldingRequest, PlanFoldingResponse

NS = "/tensegrity_sim"
PULLS = ["pull1", "pull2", "pull3", "pull4"]
WAIT = 600.0  # s of wall time: a bound on what takes seconds
TOLERANCE = 1.25  # published peak <= TOLERANCE * verified peak + SLACK
SLACK = 5.0  # N


class TestSimPlanMoving(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        rospy.init_node("test_sim_plan_moving")
        cls.lock = threading.Lock()
        cls.actuators = None
        cls.contacts = []  # (stamp, largest normal force) per ~contacts message
        rospy.Subscriber(NS + "/actuators", JointState, cls.on_actuators)
        rospy.Subscriber(NS + "/contacts", ContactArray, cls.on_contacts)
        cls.actuation = rospy.Publisher(NS + "/actuation", ActuationCommand, queue_size=10)
        rospy.wait_for_service(NS + "/plan_folding", timeout=WAIT)
        cls.plan = rospy.ServiceProxy(NS + "/plan_folding", PlanFolding)
        cls.pause = rospy.ServiceProxy(NS + "/pause", SetBool)
        cls.reset = rospy.ServiceProxy(NS + "/reset", Trigger)
        assert wait_for(lambda: cls.actuation.get_num_connections() > 0, WAIT)
        assert wait_for(lambda: cls.actuators is not None, WAIT)

    @classmethod
    def on_actuators(cls, msg):
        with cls.lock:
            cls.actuators = msg

    @classmethod
    def on_contacts(cls, msg):
        with cls.lock:
            cls.contacts.append((msg.header.stamp.to_sec(), max([c.normal_force for c in msg.contacts] + [0.0])))

    def now(self):
        """Simulated time of the last ~actuators message."""
        with self.lock:
            return self.actuators.header.stamp.to_sec()

    def wait_until(self, t):
        self.assertTrue(wait_for(lambda: self.now() >= t, WAIT), "simulated time did not reach %.3f s" % t)

    def start(self, targets, speed):
        """From the scene's initial state: the four cables pulled in to `targets` at `speed`; returns the
        simulated time of the command."""
        self.assertTrue(self.reset().success)
        # the reset publishes at once: wait for a message of the new start (time does not go back with /clock)
        t_reset = self.now()
        self.assertTrue(wait_for(lambda: self.now() > t_reset, WAIT))
        t0 = self.now()
        self.actuation.publish(ActuationCommand(names=PULLS, targets=[targets] * 4, max_speeds=[speed]))
        return t0

    def request(self, **fields):
        req = PlanFoldingRequest(actuators=PULLS, max_speeds=[0.2], max_accelerations=[1.0], time_limit=300.0, seed=1,
                                 verify_dynamics=True, execute=True)
        for k, v in fields.items():
            setattr(req, k, v)
        return req

    def execute_and_watch(self, req, paused, label):
        """Plans with `req` (execute set), resumes when paused, and watches ~contacts until the verification's
        span has passed; returns the response and the largest contact force published meanwhile."""
        t_request = self.now()  # the state the plan starts from is at or after this
        res = self.plan(req)
        print("[ measured ] %s: %s, executed %s, verified peak %.1f N (quasi-static %.1f N), trajectory %.2f s "
              "(stop %.3f s), settled %.2f s after it, planning %.2f s: %s"
              % (label, res.status, res.executed, res.dynamic_peak_contact_force, res.peak_contact_force,
                 res.duration, res.stop_duration, res.settle_duration, res.planning_time, res.message))
        self.assertEqual(res.status, PlanFoldingResponse.EXACT_SOLUTION, res.message)
        self.assertTrue(res.dynamics_verified, res.message)
        self.assertTrue(res.executed, res.message)
        if paused:
            self.assertTrue(self.pause(False).success)
        self.wait_until(t_request + res.duration + res.settle_duration + 0.5)
        with self.lock:
            published = max([f for t, f in self.contacts if t >= t_request] + [0.0])
        print("[ measured ] %s: published peak %.1f N against %.1f N verified" % (label, published,
                                                                                 res.dynamic_peak_contact_force))
        self.assertGreater(published, 0.0)  # the fold went into contact
        self.assertLessEqual(published, TOLERANCE * res.dynamic_peak_contact_force + SLACK)
        return res

    def test_1_paused_while_the_cables_are_pulled_in(self):
        # the reproduction: 2.5 s into a 0.3 m/s pull to 1.2 m, paused, then a plan down to 0.5 m with contact
        # forces up to 400 N. Verified from the moving state the fold presses harder than 400 N (the pull's momentum
        # goes into the struts): executed with execute_unverified, and its forces are those verified
        t0 = self.start(1.2, 0.3)
        self.wait_until(t0 + 2.5)
        self.assertTrue(self.pause(True).success)
        res = self.execute_and_watch(self.request(target_height=0.5, allow_contact=True, max_contact_force=400.0,
                                                  execute_unverified=True), True, "paused 2.5 s into a 0.3 m/s pull")
        # the trajectory takes the actuators over at their rate and brakes them at 1 m/s^2 first
        self.assertAlmostEqual(res.stop_duration, 0.3, places=9)
        for v in res.trajectory.points[0].velocities:
            self.assertAlmostEqual(v, 0.3, places=9)

    def test_2_requested_while_the_cables_are_pulled_in(self):
        # no pause: the node holds the simulation from the request to the answer, so the trajectory starts where
        # the actuators are when it runs; a plan within its verified limits is executed
        t0 = self.start(1.0, 0.1)
        self.wait_until(t0 + 2.0)
        res = self.execute_and_watch(self.request(target_values=[1.2] * 4, allow_contact=True,
                                                  max_contact_force=1000.0), False,
                                     "requested 2 s into a 0.1 m/s pull")
        self.assertTrue(res.dynamics_within_limits, res.message)
        self.assertAlmostEqual(res.stop_duration, 0.1, places=9)

    def test_3_requested_while_the_tower_rings(self):
        # the actuators at rest, the structure still swinging 0.4 s after a 0.8 m/s pull to 0.8 m
        t0 = self.start(0.8, 0.8)
        self.assertTrue(wait_for(lambda: self.arrived(0.8), WAIT))
        self.wait_until(self.arrival + 0.4)
        res = self.execute_and_watch(self.request(target_height=0.5, allow_contact=True, max_contact_force=400.0,
                                                  execute_unverified=True), False, "requested while the tower rings")
        self.assertEqual(res.stop_duration, 0.0)
        self.assertGreater(self.arrival, t0)

    def arrived(self, value):
        """True once ~actuators shows every pull at `value` (self.arrival: that message's stamp)."""
        with self.lock:
            a = self.actuators
        if all(abs(p - value) < 1e-12 for p in a.position):
            self.arrival = a.header.stamp.to_sec()
            return True
        return False


if __name__ == "__main__":
    rostest.rosrun("active_tensegrity", "sim_plan_moving", TestSimPlanMoving)
