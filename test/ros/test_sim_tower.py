#!/usr/bin/python3
"""rostest of tensegrity_sim on the tower (sim_tower.test): folding by an actuation command produces
contacts; a bag recorded from the node plays back with tf and contacts intact.

The recorder and the player are synchronised on connections (the node's bus info, rosbag play
--wait-for-subscribers), not on sleeps; waits are bounds on behaviour that is missing."""
import math
import os
import shutil
import signal
import subprocess
import tempfile
import threading
import time
import unittest
from xmlrpc.client import ServerProxy

import rosbag
import rosgraph
import rospy
import rostest
from tf2_msgs.msg import TFMessage
from visualization_msgs.msg import MarkerArray

from sim_test_util import wait_for
from active_tensegrity.msg import ActuationCommand, ContactArray

NS = "/tensegrity_sim"
STRUTS = ["S%d%d" % (s, k) for s in range(1, 5) for k in range(1, 5)]
BODIES = STRUTS + ["B1", "B2", "B3", "B4"]
TOPICS = ["/tf", NS + "/contacts", NS + "/markers", NS + "/actuators"]
WAIT = 60.0  # s: bound on waiting for something that takes a few seconds at most


def recorder_connected():
    """True when the node has a live connection to a recorder (a node named /record...) on every topic in
    TOPICS (the node's bus info, as rosnode info shows it)."""
    try:
        api = rosgraph.Master("/test_sim_tower").lookupNode(NS)
        _, _, info = ServerProxy(api).getBusInfo("/test_sim_tower")
    except Exception:  # the master or the node not answering yet
        return False
    # [connection id, destination, direction, transport, topic, connected, ...]
    topics = {c[4] for c in info if c[2] == "o" and str(c[1]).startswith("/record") and c[5]}
    return set(TOPICS) <= topics


def contact_key(msg):
    """Everything in a ContactArray, as plain numbers and names (for comparing recorded and replayed)."""
    rows = []
    for c in msg.contacts:
        rows.append((c.strut_a, c.strut_b, c.point_a.x, c.point_a.y, c.point_a.z, c.normal.x, c.normal.y,
                     c.normal.z, c.penetration, c.penetration_rate, c.normal_force, c.friction_force.x,
                     c.friction_force.y, c.friction_force.z))
    return (msg.header.stamp.to_nsec(), msg.header.frame_id, tuple(rows))


class TestSimTower(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        rospy.init_node("test_sim_tower")
        cls.tmp = tempfile.mkdtemp(prefix="sim_tower_")
        cls.lock = threading.Lock()
        cls.contacts = None
        cls.markers = None
        rospy.Subscriber(NS + "/contacts", ContactArray, cls.on_contacts)
        rospy.Subscriber(NS + "/markers", MarkerArray, cls.on_markers)
        cls.actuation = rospy.Publisher(NS + "/actuation", ActuationCommand, queue_size=10)
        assert wait_for(lambda: cls.actuation.get_num_connections() > 0, WAIT)

    @classmethod
    def tearDownClass(cls):
        shutil.rmtree(cls.tmp, ignore_errors=True)

    @classmethod
    def on_contacts(cls, msg):
        with cls.lock:
            if msg.contacts:
                cls.contacts = msg

    @classmethod
    def on_markers(cls, msg):
        with cls.lock:
            if any(m.ns == "contact_forces" and m.action == m.ADD for m in msg.markers):
                cls.markers = msg

    def test_fold_into_contact_record_and_play_back(self):
        bag_path = os.path.join(self.tmp, "tower.bag")
        # its own process group: `rosbag record` is a wrapper around the recorder, and both must get the
        # SIGINT that makes the recorder close the bag (and rename it from .active)
        record = subprocess.Popen(["rosbag", "record", "-O", bag_path] + TOPICS, stdout=subprocess.DEVNULL,
                                  stderr=subprocess.DEVNULL, start_new_session=True)
        try:
            self.assertTrue(wait_for(recorder_connected, WAIT), "the recorder did not connect to the node")
            names = ["pull1", "pull2", "pull3", "pull4"]
            self.actuation.publish(ActuationCommand(names=names, targets=[0.8] * 4, max_speeds=[0.5]))
            # contact starts at an actuation of 0.638 m (paper and quasi-static study)
            self.assertTrue(wait_for(lambda: self.contacts is not None, 150), "no contact on ~contacts")
            with self.lock:
                msg = self.contacts
            self.assertEqual(msg.header.frame_id, "world")
            for c in msg.contacts:
                self.assertIn(c.strut_a, STRUTS)
                self.assertIn(c.strut_b, STRUTS)
                self.assertEqual(c.strut_a[1], c.strut_b[1])  # adjacent struts of one stage
                n = math.sqrt(c.normal.x ** 2 + c.normal.y ** 2 + c.normal.z ** 2)
                self.assertAlmostEqual(n, 1.0, places=9)
                self.assertGreater(c.penetration, 0.0)
                self.assertGreater(c.normal_force, 0.0)
                self.assertTrue(all(math.isfinite(v) for v in (c.normal_force, c.penetration, c.penetration_rate,
                                                                c.friction_force.x, c.friction_force.y,
                                                                c.friction_force.z)))
            self.assertTrue(wait_for(lambda: self.markers is not None, WAIT), "no contact arrows on ~markers")
            time.sleep(1.0)  # more of the fold in the bag
        finally:
            os.killpg(record.pid, signal.SIGINT)
            record.wait(timeout=WAIT)
        self.assertTrue(wait_for(lambda: os.path.exists(bag_path), WAIT), "the recorder did not close the bag")

        # the bag: every body frame on /tf, contacts with forces
        frames, recorded = set(), []
        with rosbag.Bag(bag_path) as bag:
            for topic, m, _ in bag.read_messages(topics=["/tf", NS + "/contacts"]):
                if topic == "/tf":
                    frames.update(t.child_frame_id for t in m.transforms)
                elif m.contacts:
                    recorded.append(contact_key(m))
        self.assertTrue(set(BODIES) <= frames, sorted(frames))
        self.assertGreater(len(recorded), 0)

        # play it back on other names; the replayed contacts and frames are the recorded ones
        replayed, replay_frames = [], set()
        lock = threading.Lock()

        def on_replay(m):
            with lock:
                if m.contacts:
                    replayed.append(contact_key(m))

        def on_replay_tf(m):
            with lock:
                replay_frames.update(t.child_frame_id for t in m.transforms)

        subs = [rospy.Subscriber("/replay/contacts", ContactArray, on_replay),
                rospy.Subscriber("/replay/tf", TFMessage, on_replay_tf)]
        # the player starts once both subscribers are connected, queues rather than drops what a slow
        # subscriber has not read yet, and stays up after the bag's end until it is stopped (a player that
        # exits takes its unsent messages with it)
        play = subprocess.Popen(["rosbag", "play", "--quiet", "--rate", "4", "--queue", "1000000", "--keep-alive",
                                 "--wait-for-subscribers", bag_path, NS + "/contacts:=/replay/contacts",
                                 "/tf:=/replay/tf", "--topics", "/tf", NS + "/contacts"],
                                stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
        try:
            self.assertTrue(wait_for(lambda: len(replayed) >= len(recorded), 5 * WAIT),
                            (len(replayed), len(recorded)))
            self.assertIsNone(play.poll(), "rosbag play exited (%s)" % play.returncode)
        finally:
            os.killpg(play.pid, signal.SIGINT)
            play.wait(timeout=WAIT)
        self.assertEqual(play.returncode, 0)
        for s in subs:
            s.unregister()
        with lock:
            self.assertEqual(replayed, recorded)
            self.assertTrue(set(BODIES) <= replay_frames)


if __name__ == "__main__":
    rostest.rosrun("active_tensegrity", "sim_tower", TestSimTower)
