"""One MCAP file being written: opened, its writer started, finished once. The base of every MCAP writer here.

The fabric's recordings (:class:`fabric.recording.sink.McapSink`) and the exports to Foxglove and ROS 2
(``user_peer.openfmt``) write different records through different writers (mcap's own, mcap_ros2's), but
open and finish a file the same way: that part is here, once. A writer that fails to start leaves no
open file behind; ``close()`` writes the summary and footer and closes the file even when finishing fails.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any, BinaryIO, Callable

from mcap.writer import CompressionType, Writer

__all__ = ["McapFile", "mcap_writer"]


def mcap_writer(
    profile: str, *, compression: CompressionType = CompressionType.ZSTD, **options: Any
) -> Callable[[BinaryIO], Writer]:
    """A ``make_writer`` for :class:`McapFile`: mcap's own writer, started with ``profile`` (``options``:
    ``chunk_size`` and the rest of :class:`mcap.writer.Writer`'s)."""

    def make(file: BinaryIO) -> Writer:
        writer = Writer(file, compression=compression, **options)
        writer.start(profile=profile, library="robofabric")
        return writer

    return make


class McapFile:
    """An MCAP file at ``path``, written through ``self.writer`` (what ``make_writer(file)`` returned, started).

    ``close()`` finishes it (summary, footer), flushes, fsyncs when ``fsync`` is set, and closes the file;
    it is idempotent, and a context manager calls it on exit."""

    def __init__(self, path: str | Path, make_writer: Callable[[BinaryIO], Any], *, fsync: bool = False) -> None:
        self.path = Path(path)
        self.fsync = fsync
        self.file: BinaryIO = open(self.path, "wb")
        try:
            self.writer = make_writer(self.file)
        except BaseException:
            self.file.close()
            raise
        self._finished = False

    @property
    def closed(self) -> bool:
        return self._finished

    def close(self) -> None:
        if self._finished:
            return
        self._finished = True
        try:
            self.writer.finish()
            self.file.flush()
            if self.fsync:
                os.fsync(self.file.fileno())
        finally:
            self.file.close()

    def __enter__(self) -> McapFile:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
