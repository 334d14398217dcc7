"""fabric.recording.mcap_file: every MCAP writer opens, starts and finishes its file the one way: a finished
file is complete (summary and footer) whatever wrote it, closing twice is closing once, and a writer that
fails to start or to finish leaves no open file behind."""

from __future__ import annotations

import pytest
from mcap.reader import make_reader
from mcap_ros2.writer import Writer as Ros2McapWriter

from fabric.recording.mcap_file import McapFile, mcap_writer


@pytest.mark.parametrize("make_writer", [mcap_writer("demo"), Ros2McapWriter], ids=["mcap", "mcap_ros2"])
def test_a_closed_file_is_complete_and_closing_again_does_nothing(tmp_path, make_writer):
    out = McapFile(tmp_path / "a.mcap", make_writer)
    with out:
        assert not out.closed
    assert out.closed and out.file.closed
    out.close()
    with open(tmp_path / "a.mcap", "rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None and summary.statistics is not None and summary.statistics.message_count == 0


def test_a_writer_that_fails_to_start_leaves_no_open_file(tmp_path):
    opened = []

    def broken(file):
        opened.append(file)
        raise RuntimeError("no writer")

    with pytest.raises(RuntimeError, match="no writer"):
        McapFile(tmp_path / "b.mcap", broken)
    assert opened and opened[0].closed


def test_a_failing_finish_still_closes_the_file(tmp_path):
    class Unfinishable:
        def finish(self) -> None:
            raise OSError("disk full")

    out = McapFile(tmp_path / "c.mcap", lambda _f: Unfinishable())
    with pytest.raises(OSError, match="disk full"):
        out.close()
    assert out.closed and out.file.closed
