"""A recording carries its world's description (the recorder writes ``srv/world``'s answer when a sim comes),
so an export needs no ``--scene``: the arm of the combined scene is placed on its table, (3.0, 0, 0.75), read
back with mcap-protobuf-support's decoder. A recording without a description says so."""

from __future__ import annotations

import logging

import pytest
from mcap.reader import make_reader
from mcap_protobuf.decoder import DecoderFactory as ProtobufDecoders

from fabric import keys
from fabric.codec import encode
from fabric.interfaces import Header, JointState
from fabric.recording import McapSink, Recorder
from user_peer.recordings import iter_messages
from robofabric.testing import robofabric_cmd, wait_until
from user_peer.openfmt import export_recording

pytestmark = pytest.mark.slow


def _arm_base(path) -> set[tuple[float, float, float]]:
    out = set()
    with open(path, "rb") as f:
        for _s, _c, _m, msg in make_reader(f, decoder_factories=[ProtobufDecoders()]).iter_decoded_messages(
            topics=["/tf"]
        ):
            for t in msg.transforms:
                if t.child_frame_id == "arm1/base_link":  # the URDF's root link, bolted to map
                    out.add((round(t.translation.x, 6), round(t.translation.y, 6), round(t.translation.z, 6)))
    return out


def test_a_recording_made_without_scene_exports_the_arm_on_its_table(world, router, connect, procs, tmp_path, caplog):
    sim = procs.start(
        robofabric_cmd(
            "sim", "--scene", "combined", "--world", world, "--connect", f"tcp/127.0.0.1:{router[1]}", "--id", "sim-a"
        ),
        name="sim",
    )
    path = tmp_path / "run.mcap"
    rec = Recorder(connect("recorder", "rec"), path).start()
    try:
        wait_until(
            lambda: rec.described >= 1 and rec.stats.messages > 300,
            timeout=90,
            what="the world described and recorded",
            seen=lambda: (rec.described, rec.stats, procs.output(sim)[-800:]),
        )
    finally:
        rec.close()
    assert [m.key for m in iter_messages(path, keys.srv(world, "world"))], "no world description in the recording"
    out = tmp_path / "fox.mcap"
    with caplog.at_level(logging.WARNING, logger="robofabric"):
        export_recording(path, out, "foxglove")  # no scene
    assert "no world description" not in caplog.text
    assert _arm_base(out) == {(3.0, 0.0, 0.75)}


def test_a_recording_without_a_description_says_so(tmp_path, caplog):
    path = tmp_path / "old.mcap"
    with McapSink(path) as sink:
        for i in range(5):
            js = JointState(
                tuple(f"joint_{j}" for j in range(1, 7)), [0.0] * 6, [0.0] * 6, Header(i * 0.01, 0, i, "sim")
            )
            sink.write("rf/demo/robot/arm1/joints", encode(js), 1_000 + i)
    with caplog.at_level(logging.WARNING, logger="robofabric"):
        export_recording(path, tmp_path / "fox.mcap", "foxglove")
    assert "carries no world description" in caplog.text and "--scene" in caplog.text
