"""Files written by the sink, read back by the mcap package's own readers and by ours; finished, torn and bad."""

import io
import json
from collections import Counter

import pytest
from hypothesis import HealthCheck, given, settings, strategies as st
from mcap.reader import NonSeekingReader, make_reader

from fabric.recording import MESSAGE_ENCODING
from user_peer.recordings import RecordingError, iter_messages, read_info, read_samples

from rec_helpers import synthetic, write_recording


def test_mcap_reader_sees_channels_schemas_encodings_and_times(tmp_path):
    samples = synthetic("w")
    path = tmp_path / "a.mcap"
    write_recording(path, samples)
    with open(path, "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        got = [
            (ch.topic, schema.name if schema else None, ch.message_encoding, m.log_time, m.publish_time, m.data)
            for schema, ch, m in reader.iter_messages(log_time_order=False)
        ]
    assert summary.statistics.message_count == len(samples)
    assert {c.topic for c in summary.channels.values()} == {k for k, _, _ in samples}
    assert all(c.compression == "zstd" for c in summary.chunk_indexes)
    assert [(k, t, p) for k, _, _, t, _, p in got] == samples
    assert {enc for _, _, enc, _, _, _ in got} == {MESSAGE_ENCODING}
    schemas = {k: s for k, s, *_ in got}
    assert schemas["rf/w/robot/r0/joints"] == "JointState" and schemas["rf/w/robot/r0/scan"] == "Scan"
    assert schemas["rf/w/event/blob"] == "raw"
    # publish time is the header's wall time; the raw blob has none, so it is its receive time
    first = got[0]
    assert first[4] == first[3] - 1000
    assert got[-1][4] == got[-1][3]


def test_info_counts_rates_sizes_and_status(tmp_path):
    samples = synthetic("w", n=101)
    path = tmp_path / "a.mcap"
    write_recording(path, samples, compression="lz4")
    info = read_info(path)
    assert info.complete and info.status == "complete"
    assert info.messages == len(samples)
    assert info.payload_bytes == sum(len(p) for _, _, p in samples)
    by_key = {c.key: c for c in info.channels}
    assert by_key["rf/w/robot/r0/joints"].messages == 101
    assert by_key["rf/w/robot/r0/joints"].rate_hz == pytest.approx(100.0, rel=1e-6)
    assert by_key["rf/w/robot/r0/pose"].rate_hz == pytest.approx(50.0, rel=1e-6)
    assert info.worlds == ("w",) and "raw" in info.schemas and info.compression == ("lz4",)
    assert json.loads(json.dumps(info.to_json()))["messages"] == len(samples)


def test_iter_messages_filters_by_key_expression_and_window(tmp_path):
    samples = synthetic("w")
    path = tmp_path / "a.mcap"
    write_recording(path, samples)
    got = list(iter_messages(path, "rf/w/robot/*/joints"))
    assert [(m.key, m.log_time, m.payload) for m in got] == [s for s in samples if s[0].endswith("joints")]
    t0 = samples[0][1]
    window = list(iter_messages(path, start_ns=t0 + 100_000_000, end_ns=t0 + 200_000_000))
    assert window and all(t0 + 100_000_000 <= m.log_time < t0 + 200_000_000 for m in window)
    with pytest.raises(RecordingError, match="not a valid key expression"):
        list(iter_messages(path, "rf/w/**/**/x$"))


def _complete_chunk_messages(data: bytes) -> int:
    """Messages the mcap package's streaming reader delivers before a torn file stops it."""
    n = 0
    try:
        for _schema, _ch, _m in NonSeekingReader(io.BytesIO(data)).iter_messages(log_time_order=False):
            n += 1
    except Exception:
        pass
    return n


def test_a_file_cut_anywhere_reads_up_to_its_last_complete_chunk(tmp_path):
    samples = synthetic("w", n=200)
    full = tmp_path / "full.mcap"
    # small chunks so that a cut lands between many of them
    write_recording(full, samples, chunk_size=2048)
    data = full.read_bytes()
    n_chunks = read_info(full).chunks
    assert n_chunks > 5
    cut_path = tmp_path / "cut.mcap"
    seen_partial = False
    for cut in range(64, len(data) - 1, max(1, len(data) // 97)):
        cut_path.write_bytes(data[:cut])
        info = read_info(cut_path)
        assert not info.complete and "truncated" in info.detail
        ours = [(m.key, m.log_time, m.payload) for m in iter_messages(cut_path)]
        assert ours == samples[: len(ours)]  # a prefix, byte for byte
        assert len(ours) == info.messages == _complete_chunk_messages(data[:cut])
        seen_partial |= 0 < len(ours) < len(samples)
    assert seen_partial


@pytest.mark.parametrize(
    "content, why",
    [
        (None, "no such file"),
        (b"", "empty file"),
        (b"PK\x03\x04 this is a zip", "not an MCAP file"),
        (b"\x89MCAP", "truncated beyond repair"),
        (b"\x89MCAP0\r\n\x05\x00\x00", "truncated beyond repair"),
    ],
)
def test_bad_files_are_refused_with_one_line(tmp_path, content, why):
    path = tmp_path / "bad.mcap"
    if content is not None:
        path.write_bytes(content)
    with pytest.raises(RecordingError, match=why) as exc:
        read_info(path)
    assert "\n" not in str(exc.value)


def test_a_directory_is_not_a_recording(tmp_path):
    with pytest.raises(RecordingError, match="not a file"):
        read_info(tmp_path)


def test_per_key_counts_survive_a_round_trip(tmp_path):
    samples = synthetic("w", n=30)
    path = tmp_path / "a.mcap"
    write_recording(path, samples)
    assert Counter(m.key for m in iter_messages(path)) == Counter(k for k, _, _ in samples)
    assert [(k, t, p) for k, t, _pt, p in read_samples(path)] == samples


_keys = st.sampled_from(["rf/w/robot/a/joints", "rf/w/robot/b/scan", "rf/v/event/x", "rf/w/map/m"])


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(
    st.lists(st.tuples(_keys, st.integers(0, 10**6), st.binary(max_size=2000)), max_size=60),
    st.sampled_from(["zstd", "lz4", "none"]),
    st.sampled_from([1024, 1 << 20]),
)
def test_whatever_is_written_is_read_back_exactly(tmp_path, items, compression, chunk_size):
    t = 1_000_000_000
    samples = []
    for key, dt, payload in items:
        t += dt
        samples.append((key, t, payload))
    path = tmp_path / "h.mcap"
    write_recording(path, samples, compression=compression, chunk_size=chunk_size)
    assert [(m.key, m.log_time, m.payload) for m in iter_messages(path)] == samples
    with open(path, "rb") as f:
        mine = [(c.topic, m.log_time, m.data) for _s, c, m in make_reader(f).iter_messages(log_time_order=False)]
    assert mine == samples
    assert read_info(path).complete


def test_the_sink_counts_what_the_publishers_numbered_and_never_reached_it(tmp_path):
    """A stall at load: zenoh dropped 184 of a base's poses on the way, and the recording must say so."""
    from fabric.recording import McapSink
    from fabric.recording.recorder import RecorderStats

    from rec_helpers import joint_payload

    t0 = 1_700_000_000_000_000_000
    with McapSink(tmp_path / "a.mcap") as sink:
        for seq in [*range(100), *range(284, 300)]:  # seq 100-283 never came
            sink.write("rf/w/robot/arm0/joints", joint_payload(seq, t0 + seq), t0 + seq)
        for seq in range(50):  # another publisher of the same key: its own numbering, complete
            sink.write("rf/w/robot/arm0/joints", joint_payload(seq, t0 + seq, source="sim-b"), t0 + seq)
        sink.write("rf/w/event/blob", b"\x00not a fabric message", t0)
        assert (sink.gaps.missed, sink.gaps.holes) == (184, 1)
    line = RecorderStats(166, 0, 0, 1, 1.0, 0, 1, 0, missed=184, holes=1).line()
    assert "MISSED 184 msgs on the way (in 1 hole)" in line
    assert "MISSED" not in RecorderStats(166, 0, 0, 1, 1.0, 0, 1, 0).line()
