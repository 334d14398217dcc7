"""The live converter (``record --to FORMAT``) as a resource: a context manager that owns its writer."""

from __future__ import annotations

import numpy as np
import pytest

from fabric import keys
from fabric.interfaces import Header, JointState
from robofabric.recording.live_convert import LiveConverter
from robofabric.testing import wait_until


class ListSink:
    """A writer that keeps what it is given (the ``write``/``close`` contract of the exporters)."""

    def __init__(self) -> None:
        self.got: list[tuple[str, object]] = []
        self.closed = 0

    def write(self, key: str, msg: object, log_time_ns: int, publish_time_ns: int) -> None:
        self.got.append((key, msg))

    def close(self) -> None:
        self.closed += 1


def test_the_converter_is_a_context_manager_that_finishes_its_writer(world, connect):
    pub, fab = connect("tool"), connect("recorder")
    key = keys.robot_joints(world, "arm1")
    sink = ListSink()
    conv = LiveConverter(fab, sink, [keys.world_all(world)])
    with conv as same:
        assert same is conv and conv.start() is conv  # start is idempotent

        def publish_and_look() -> list:
            pub.publish(key, JointState(("j",), np.zeros(1), np.zeros(1), Header.now(source="test")))
            return sink.got

        wait_until(publish_and_look, timeout=20, what="a converted message")
    assert sink.closed == 1 and conv.stats.written >= 1 and sink.got[0][0] == key
    conv.close()
    assert sink.closed == 1  # stop is idempotent
    with pytest.raises(RuntimeError, match="stopped"):
        conv.start()


def test_a_converter_never_started_still_finishes_its_writer(world, connect):
    sink = ListSink()
    conv = LiveConverter(connect("recorder"), sink, [keys.world_all(world)])
    assert conv.close().written == 0 and sink.closed == 1
