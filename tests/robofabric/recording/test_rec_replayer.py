"""Replay planning and scheduling, on a fake clock: what goes out, on which key, exactly when."""

import threading

import pytest

from fabric.rate import FakeClock
from user_peer.recordings import RecordingError
from robofabric.recording import Replayer, due_time, plan_replay

from tests.fabric.recording.rec_helpers import synthetic, write_recording

T0 = 1_700_000_000_000_000_000


@pytest.fixture
def rec(tmp_path):
    samples = synthetic("w", n=50, t0=T0)
    path = tmp_path / "a.mcap"
    write_recording(path, samples)
    return path, samples


def _play(plan, *, loop=False, passes=None):
    clock = FakeClock(100.0)
    sent = []
    stop = threading.Event()

    def publish(key, payload):
        sent.append((clock.now(), key, payload))
        if passes is not None and len(sent) >= passes:
            stop.set()

    stats = Replayer(publish, plan, loop=loop, clock=clock).run(stop)
    return sent, stats


def test_due_time_is_on_one_absolute_timeline():
    assert due_time(T0 + 2_000_000_000, T0, 2.0, 10.0) == pytest.approx(11.0)
    assert due_time(T0, T0, 1.0, 10.0, loop_index=3, loop_len=5.0) == pytest.approx(25.0)


@pytest.mark.parametrize("speed", [1.0, 2.0, 0.5])
def test_every_message_goes_out_byte_identical_at_its_scaled_time(rec, speed):
    path, samples = rec
    plan = plan_replay(path, speed=speed)
    sent, stats = _play(plan)
    assert [(k, p) for _, k, p in sent] == [(k, p) for k, _, p in samples]
    for (t, _, _), (_, log_t, _) in zip(sent, samples):
        assert t == pytest.approx(100.0 + (log_t - T0) / 1e9 / speed, abs=1e-9)
    assert stats.messages == len(samples) and stats.late_max_ms == pytest.approx(0.0, abs=1e-6)


def test_keys_filter_window_and_remap(rec):
    path, samples = rec
    plan = plan_replay(path, keys="rf/w/robot/r0/**", start=0.1, end=0.3, remap_world="x")
    sent, _ = _play(plan)
    want = [
        (k.replace("rf/w/", "rf/x/"), t, p)
        for k, t, p in samples
        if k.startswith("rf/w/robot/r0/") and T0 + 100_000_000 <= t < T0 + 300_000_000
    ]
    assert [(k, p) for _, k, p in sent] == [(k, p) for k, _, p in want]
    # the window's start is the timeline's zero
    assert sent[0][0] == pytest.approx(100.0 + (want[0][1] - T0 - 100_000_000) / 1e9, abs=1e-9)
    assert plan.keys == ("rf/w/robot/r0/joints", "rf/w/robot/r0/pose", "rf/w/robot/r0/scan")


def test_loop_starts_again_one_pass_later(rec):
    path, samples = rec
    plan = plan_replay(path, keys=["rf/w/robot/r1/joints"])
    n = plan.messages
    sent, stats = _play(plan, loop=True, passes=2 * n + 1)
    assert [p for _, _, p in sent[:n]] == [p for _, _, p in sent[n : 2 * n]]
    assert sent[n][0] - sent[0][0] == pytest.approx(plan.loop_len_s, abs=1e-9)
    assert plan.loop_len_s == pytest.approx(0.5, abs=1e-6)  # 50 ticks of 10 ms: span + one mean gap
    assert stats.loops == 2


@pytest.mark.parametrize(
    "kwargs, why",
    [
        (dict(world="nope"), "world 'nope' is not in"),
        (dict(keys="rf/w/robot/zz/**"), "nothing in .* matches"),
        (dict(keys="rf/other/**"), "nothing in .* matches"),
        (dict(speed=0), "--speed must be a positive"),
        (dict(speed=float("nan")), "--speed must be a positive"),
        (dict(start=-1), "--start must be"),
        (dict(start=2.0, end=1.0), "--end .* must be after"),
        (dict(start=100.0), "no selected message between"),
        (dict(remap_world="a/b"), "--remap-world"),
    ],
)
def test_impossible_replays_are_refused_before_anything_is_sent(rec, kwargs, why):
    path, _ = rec
    with pytest.raises(RecordingError, match=why) as exc:
        plan_replay(path, **kwargs)
    assert "\n" not in str(exc.value)


def test_the_replayer_runs_once_on_its_thread_and_close_ends_it(rec):
    """``with`` starts the replay on one thread (a second start does nothing); leaving it ends the replay,
    waits for the thread and marks it done; close is idempotent, and a closed replayer never starts."""
    from robofabric.testing import wait_until

    path, _ = rec
    sent = []
    rp = Replayer(lambda key, payload: sent.append(key), plan_replay(path), loop=True, clock=FakeClock(100.0))
    assert not rp.done
    with rp:
        rp.start()
        wait_until(lambda: rp.stats.loops >= 2, what="a looping replay past its second pass", seen=lambda: rp.stats)
        assert sum(t.name == "replayer" for t in threading.enumerate()) == 1 and not rp.done
    assert rp.done and rp.error is None and not any(t.name == "replayer" for t in threading.enumerate())
    n = len(sent)
    rp.close()
    rp.start()
    assert len(sent) == n and rp.stats.messages == n and rp.stats.loops >= 2
