"""The bridge's garbage-collection pause recorder: every collection while it records, none after ``close()``."""

import gc


import rclpy  # noqa: E402,F401  (the test extra installs ROS 2 Kilted's wheels: missing, these tests fail)

from user_peer.ros2.pauses import GcPauses  # noqa: E402


def test_a_collection_while_recording_is_timed_with_its_generation_and_none_after_close():
    rec = GcPauses()
    try:
        gc.collect()
        full = [p for p in rec.pauses if p[0] == 2]
        assert full, rec.pauses
        assert all(start <= end for _, start, end in rec.pauses)
    finally:
        rec.close()
    n = len(rec.pauses)
    gc.collect()
    assert len(rec.pauses) == n
    rec.close()  # idempotent
