"""Shared by the rostest nodes in test/ros (imported from the scripts' own folder)."""
import time


def wait_for(predicate, timeout, step=0.02):
    """Polls predicate until it is true or timeout (s) has passed; returns its last value."""
    end = time.time() + timeout
    while time.time() < end:
        if predicate():
            return True
        time.sleep(step)
    return predicate()
