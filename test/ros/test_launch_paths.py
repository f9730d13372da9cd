#!/usr/bin/python3
"""rostest of the launch files' paths (launch_paths.test): roslaunch started in a temporary folder takes
relative bag and scene paths from there (not from $ROS_HOME, where its nodes run) and fails with exit
status 1 and a message on a bag that does not exist or a bag folder that does not exist; sim.launch
records and publishes /clock only when asked to."""
import os
import shutil
import signal
import subprocess
import tempfile
import unittest

import rosbag
import rospy
import rostest
from std_msgs.msg import String

from sim_test_util import wait_for

from active_tensegrity.msg import SimStatus

PROBE = "/launch_paths/probe"


def roslaunch_args(launch_file, *args):
    return ["roslaunch", "--screen", "active_tensegrity", launch_file] + list(args)


def stop(proc, timeout=60):
    """SIGINT to roslaunch (it stops its nodes), then SIGKILL to its whole process group; returns its output."""
    proc.send_signal(signal.SIGINT)
    try:
        out, _ = proc.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        out, _ = proc.communicate()
    return out


class TestLaunchPaths(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        rospy.init_node("test_launch_paths")
        here = os.path.dirname(os.path.abspath(__file__))
        cls.scene = os.path.join(here, "..", "..", "config", "scenes", "prism.yaml")

    def setUp(self):
        self.dir = tempfile.mkdtemp(prefix="launch_paths_")
        self.env = dict(os.environ, PWD=self.dir)

    def tearDown(self):
        shutil.rmtree(self.dir, ignore_errors=True)

    def start_launch(self, *args):
        # a process group of its own, so that nothing it started outlives a failed test
        return subprocess.Popen(args, cwd=self.dir, env=self.env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                                universal_newlines=True, start_new_session=True)

    def run_launch(self, *args, timeout=60):
        """Runs roslaunch to its end; returns (exit status, output); stopped after timeout (status None)."""
        proc = self.start_launch(*args)
        try:
            out, _ = proc.communicate(timeout=timeout)
            return proc.returncode, out
        except subprocess.TimeoutExpired:
            return None, stop(proc) + "\n(stopped after %d s)" % timeout

    def test_01_missing_bag_exits_1_with_a_message(self):
        rc, out = self.run_launch(*roslaunch_args("playback.launch", "bag:=missing.bag", "rviz:=false"))
        self.assertEqual(rc, 1, out)
        self.assertIn("no bag file at %s/missing.bag" % self.dir, out)

    def test_02_relative_bag_is_played_from_the_callers_folder(self):
        with rosbag.Bag(os.path.join(self.dir, "small.bag"), "w") as bag:
            for i in range(30):
                bag.write(PROBE, String(data="probe %d" % i), rospy.Time(1000.0 + 0.1 * i))
        received = []
        sub = rospy.Subscriber(PROBE, String, received.append)
        try:
            rc, out = self.run_launch(*roslaunch_args("playback.launch", "bag:=small.bag", "rviz:=false"))
        finally:
            sub.unregister()
        self.assertEqual(rc, 0, out)
        self.assertNotIn("ERROR", out)
        self.assertGreater(len(received), 0, out)

    def test_03_relative_record_and_scene_paths_are_the_callers(self):
        shutil.copy(self.scene, os.path.join(self.dir, "my_prism.yaml"))
        statuses = []
        sub = rospy.Subscriber("/rec_sim/status", SimStatus, statuses.append)
        bag = os.path.join(self.dir, "rec.bag")
        proc = self.start_launch(*roslaunch_args("sim.launch", "node_name:=rec_sim", "scene:=my_prism.yaml",
                                                 "rviz:=false", "real_time_factor:=0", "max_publish_wall_rate:=50",
                                                 "record:=rec.bag"))
        # uncapped, real_time_factor 0 publishes thousands of messages per wall second: rosbag record's buffer
        # overflows and drops the oldest, the once-a-second status among them (as docs/ros.md says, cap it)
        try:
            started = wait_for(lambda: statuses and (os.path.exists(bag + ".active") or os.path.exists(bag)), 90, 0.1)
            # two more of the node's once-a-second statuses: the recorder has been subscribed for a full period at
            # least, on a loaded machine too (a fixed second was not always enough for its subscriptions)
            seen = len(statuses)
            recorded = started and wait_for(lambda: len(statuses) >= seen + 2, 30, 0.1)
        finally:
            sub.unregister()
            out = stop(proc)
        self.assertTrue(started, out)
        self.assertTrue(recorded, out)
        self.assertTrue(wait_for(lambda: os.path.exists(bag), 10, 0.1), out)
        self.assertGreater(os.path.getsize(bag), 0)
        # the node's data topics, ~struts among them (sim.launch recorded every one but that)
        with rosbag.Bag(bag) as b:
            topics = set(b.get_type_and_topic_info().topics)
        for topic in ("/tf", "/rec_sim/struts", "/rec_sim/contacts", "/rec_sim/cables", "/rec_sim/actuators",
                      "/rec_sim/status"):
            self.assertIn(topic, topics, out)
        ros_home = os.environ.get("ROS_HOME") or os.path.expanduser("~/.ros")
        self.assertFalse(os.path.exists(os.path.join(ros_home, "rec.bag")))

    def test_04_record_into_a_missing_folder_exits_1_with_a_message(self):
        rc, out = self.run_launch(*roslaunch_args("sim.launch", "node_name:=rec_sim", "rviz:=false",
                                                  "record:=no_such_folder/rec.bag"))
        self.assertEqual(rc, 1, out)
        self.assertIn("no directory %s/no_such_folder" % self.dir, out)


    def test_05_without_record_no_bag_and_no_clock(self):
        args = ["active_tensegrity", "sim.launch", "rviz:=false"]
        rc, out = self.run_launch("roslaunch", "--nodes", *args)
        self.assertEqual(rc, 0, out)
        self.assertEqual(out.split(), ["/tensegrity_sim"])
        rc, out = self.run_launch("roslaunch", "--dump-params", *args)
        self.assertEqual(rc, 0, out)
        self.assertIn("/use_sim_time: false", out)
        self.assertIn("/tensegrity_sim/publish_clock: false", out)
        rc, out = self.run_launch("roslaunch", "--nodes", *(args + ["record:=x.bag"]))
        self.assertEqual(rc, 0, out)
        self.assertEqual(sorted(out.split()), ["/record", "/tensegrity_sim"])

if __name__ == "__main__":
    rostest.rosrun("active_tensegrity", "launch_paths", TestLaunchPaths)
