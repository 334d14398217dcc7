"""Recordings in formats other tools open: Foxglove (protobuf well-known schemas + JSON Schema'd JSON) and ROS 2 (CDR).

``open_sink(to, path)`` gives a writer with ``write(key, message, log_time_ns, publish_time_ns)``
and ``close()``; :func:`export_recording` feeds it a fabric MCAP recording, and ``robofabric
record --to`` feeds it live samples (found through the entry-point group ``robofabric.exporters``).
See docs/recording.md ("Foxglove and ROS 2").
"""

from user_peer.openfmt.convert import FORMATS, ExportStats, export_recording, open_sink

__all__ = ["FORMATS", "ExportStats", "export_recording", "open_sink"]
