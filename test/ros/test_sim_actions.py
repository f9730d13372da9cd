#!/usr/bin/python3
"""rostest of tensegrity_sim's actions on the tower (sim_actions.test).

Waits are generous bounds that only guard against hangs: no outcome depends on the machine's speed. The
follow cases run in simulated time (the node steps at real time here; stamps are simulated time)."""
import math
import threading
import unittest

import actionlib
import rospy
import rostest
from actionlib_msgs.msg import GoalStatus
from sensor_msgs.msg import JointState
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from sim_test_util import wait_for
from active_tensegrity.msg import (ActuationCommand, FollowTrajectoryAction, FollowTrajectoryGoal,
                                   FollowTrajectoryResult, PlanFoldingAction, PlanFoldingGoal, PlanFoldingResult)

NS = "/tensegrity_sim"
PULLS = ["pull1", "pull2", "pull3", "pull4"]


def trajectory(names, points):
    """points: [(seconds from start, [value per name]), ...]"""
    t = JointTrajectory(joint_names=names)
    t.points = [JointTrajectoryPoint(positions=p, time_from_start=rospy.Duration(s)) for s, p in points]
    return t


class Feedback:
    def __init__(self):
        self.lock = threading.Lock()
        self.messages = []

    def __call__(self, msg):
        with self.lock:
            self.messages.append(msg)

    def count(self):
        with self.lock:
            return len(self.messages)

    def all(self):
        with self.lock:
            return list(self.messages)


class TestSimActions(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        rospy.init_node("test_sim_actions")
        cls.lock = threading.Lock()
        cls.actuators = None
        rospy.Subscriber(NS + "/actuators", JointState, cls.on_actuators)
        cls.actuation = rospy.Publisher(NS + "/actuation", ActuationCommand, queue_size=10)
        cls.planner = actionlib.SimpleActionClient(NS + "/plan_folding", PlanFoldingAction)
        cls.follower = actionlib.SimpleActionClient(NS + "/follow_trajectory", FollowTrajectoryAction)
        cls.other = actionlib.SimpleActionClient(NS + "/follow_trajectory", FollowTrajectoryAction)
        for client in (cls.planner, cls.follower, cls.other):
            assert client.wait_for_server(rospy.Duration(120)), "no action server"
        assert wait_for(lambda: cls.actuators is not None, 120)

    @classmethod
    def on_actuators(cls, msg):
        with cls.lock:
            cls.actuators = msg

    def values(self, names):
        with self.lock:
            a = self.actuators
        return [a.position[a.name.index(n)] for n in names]

    def test_1_plan_action_reports_progress_and_plans(self):
        feedback = Feedback()
        self.planner.send_goal(PlanFoldingGoal(actuators=PULLS, target_height=0.5, allow_contact=True,
                                               max_contact_force=400.0, time_limit=300.0, seed=1),
                               feedback_cb=feedback)
        self.assertTrue(self.planner.wait_for_result(rospy.Duration(600)))
        res = self.planner.get_result()
        self.assertEqual(self.planner.get_state(), GoalStatus.SUCCEEDED,
                         "status %s after %.2f s, %d solves: %s" % (res.status, res.planning_time,
                                                                    res.equilibrium_solves, res.message))
        self.assertEqual(res.status, PlanFoldingResult.EXACT_SOLUTION, res.message)
        self.assertLessEqual(res.final_height, 0.5)
        self.assertFalse(res.cancelled)
        self.assertGreater(len(res.trajectory.points), 1)
        msgs = feedback.all()
        self.assertGreater(len(msgs), 0)
        solves = [m.equilibrium_solves for m in msgs]
        self.assertEqual(solves, sorted(solves))
        self.assertLessEqual(solves[-1], res.equilibrium_solves)
        print("[ measured ] plan action: %d feedback messages, phases %s, %d solves, %.2f s"
              % (len(msgs), sorted(set(m.phase for m in msgs)), res.equilibrium_solves, res.planning_time))

    def test_2_a_cancelled_plan_answers_with_what_it_has(self):
        # below 0.5 m without contact is impossible: without the early check the search would run 300 s
        feedback = Feedback()
        self.planner.send_goal(PlanFoldingGoal(actuators=PULLS, target_height=0.5, min_clearance=0.005,
                                               skip_reachability_check=True, time_limit=300.0, seed=1),
                               feedback_cb=feedback)
        self.assertTrue(wait_for(lambda: feedback.count() > 0, 120))
        self.planner.cancel_goal()
        self.assertTrue(self.planner.wait_for_result(rospy.Duration(120)))
        self.assertEqual(self.planner.get_state(), GoalStatus.PREEMPTED)
        res = self.planner.get_result()
        self.assertTrue(res.cancelled, res.message)
        self.assertFalse(res.stopped_by_time_limit, res.message)
        self.assertNotEqual(res.status, PlanFoldingResult.EXACT_SOLUTION)
        # every best height the feedback reported before the answer is reached by the path returned (the search can
        # only have done better since its last report)
        before = [m.best_height for m in feedback.all() if m.phase != "done"]
        if res.trajectory.points:
            self.assertLessEqual(res.final_height, min(before) + 1e-12)
        # the feedback sent with the answer ('done') describes the path returned (its end; +inf without one); it
        # travels on another topic than the result, and actionlib may drop the feedback of a goal it saw finish
        wait_for(lambda: feedback.all()[-1].phase == "done", 10)
        done = [m for m in feedback.all() if m.phase == "done"]
        if done:
            self.assertEqual(done[-1].best_height, res.final_height if res.trajectory.points else float("inf"))
            self.assertEqual(done[-1].equilibrium_solves, res.equilibrium_solves)
        print("[ measured ] cancelled plan: %s after %.2f s, final height %.4f m, best height in the feedback before "
              "the answer %.4f m (%s)" % (res.status, res.planning_time, res.final_height, before[-1] if before else
                                          float("inf"), res.message))

    def test_3_a_trajectory_is_followed_with_feedback(self):
        start = self.values(PULLS)
        feedback = Feedback()
        end = [v + 0.05 for v in start]
        self.follower.send_goal(FollowTrajectoryGoal(trajectory=trajectory(PULLS, [(1.0, end)]), path_tolerance=1e-6),
                                feedback_cb=feedback)
        self.assertTrue(self.follower.wait_for_result(rospy.Duration(300)))
        self.assertEqual(self.follower.get_state(), GoalStatus.SUCCEEDED, self.follower.get_goal_status_text())
        res = self.follower.get_result()
        self.assertEqual(res.error_code, FollowTrajectoryResult.SUCCESSFUL, res.error_string)
        msgs = feedback.all()
        self.assertGreater(len(msgs), 0)
        for m in msgs:
            self.assertEqual(m.joint_names, PULLS)
            self.assertEqual(len(m.desired), 4)
            for d, a, e in zip(m.desired, m.actual, m.error):
                self.assertAlmostEqual(e, d - a, places=12)
                self.assertLessEqual(abs(e), 1e-6)  # nothing else drives them: the simulation follows exactly
        # at the end once the published values catch up (the result can arrive before the joint states of its
        # last step: reading them at once raced, 0.0473 of 0.05 m seen under load)
        self.assertTrue(wait_for(lambda: all(abs(v - e) < 1e-9 for v, e in zip(self.values(PULLS), end)), 60),
                        "joint states %s, expected %s" % (self.values(PULLS), end))

    def test_4_an_invalid_goal_is_refused_and_the_simulation_runs_on(self):
        self.follower.send_goal(FollowTrajectoryGoal(trajectory=trajectory(["pull1", "nope"], [(1.0, [0.1, 0.1])])))
        self.assertTrue(self.follower.wait_for_result(rospy.Duration(120)))
        self.assertEqual(self.follower.get_state(), GoalStatus.ABORTED)
        res = self.follower.get_result()
        self.assertEqual(res.error_code, FollowTrajectoryResult.INVALID_GOAL)
        self.assertIn("'nope'", res.error_string)
        with self.lock:
            t0 = self.actuators.header.stamp.to_sec()
        self.assertTrue(wait_for(lambda: self.actuators.header.stamp.to_sec() > t0 + 0.5, 120))  # still stepping

    def test_5_another_command_breaks_the_path_tolerance(self):
        start = self.values(["pull1"])[0]
        feedback = Feedback()
        self.follower.send_goal(FollowTrajectoryGoal(trajectory=trajectory(["pull1"], [(20.0, [start + 0.2])]),
                                                     path_tolerance=1e-3), feedback_cb=feedback)
        self.assertTrue(wait_for(lambda: feedback.count() > 0, 120))
        # pull1 taken over by a ramp back to where it started
        self.actuation.publish(ActuationCommand(names=["pull1"], targets=[start], max_speeds=[0.05]))
        self.assertTrue(self.follower.wait_for_result(rospy.Duration(300)))
        self.assertEqual(self.follower.get_state(), GoalStatus.ABORTED)
        res = self.follower.get_result()
        self.assertEqual(res.error_code, FollowTrajectoryResult.PATH_TOLERANCE_VIOLATED, res.error_string)
        self.assertIn("'pull1'", res.error_string)

    def test_6_a_new_goal_preempts_the_running_one(self):
        start = self.values(["pull2"])[0]
        first = Feedback()
        self.follower.send_goal(FollowTrajectoryGoal(trajectory=trajectory(["pull2"], [(30.0, [start + 0.3])])),
                                feedback_cb=first)
        self.assertTrue(wait_for(lambda: first.count() > 0, 120))
        self.other.send_goal(FollowTrajectoryGoal(trajectory=trajectory(["pull2"], [(1.0, [start + 0.02])])))
        self.assertTrue(self.follower.wait_for_result(rospy.Duration(120)))
        self.assertEqual(self.follower.get_state(), GoalStatus.PREEMPTED)
        self.assertTrue(self.other.wait_for_result(rospy.Duration(300)))
        self.assertEqual(self.other.get_state(), GoalStatus.SUCCEEDED, self.other.get_goal_status_text())
        self.assertTrue(wait_for(lambda: abs(self.values(["pull2"])[0] - (start + 0.02)) < 1e-9, 60))

    def test_7_a_cancel_holds_the_actuators(self):
        start = self.values(["pull3"])[0]
        feedback = Feedback()
        self.follower.send_goal(FollowTrajectoryGoal(trajectory=trajectory(["pull3"], [(30.0, [start + 0.3])])),
                                feedback_cb=feedback)
        self.assertTrue(wait_for(lambda: feedback.count() > 2, 120))
        self.follower.cancel_goal()
        self.assertTrue(self.follower.wait_for_result(rospy.Duration(120)))
        self.assertEqual(self.follower.get_state(), GoalStatus.PREEMPTED)
        # held: after a short stop the value no longer changes (in simulated time)
        with self.lock:
            t0 = self.actuators.header.stamp.to_sec()
        self.assertTrue(wait_for(lambda: self.actuators.header.stamp.to_sec() > t0 + 2.0, 120))
        held = self.values(["pull3"])[0]
        with self.lock:
            t1 = self.actuators.header.stamp.to_sec()
        self.assertTrue(wait_for(lambda: self.actuators.header.stamp.to_sec() > t1 + 1.0, 120))
        self.assertEqual(self.values(["pull3"])[0], held)
        self.assertLess(held, start + 0.3)


if __name__ == "__main__":
    rostest.rosrun("active_tensegrity", "sim_actions", TestSimActions)
