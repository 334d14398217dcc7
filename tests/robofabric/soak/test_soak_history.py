"""The soak's history: every record survives a line of JSON unchanged, the files read back in time order, and a
line that does not parse is named (file and line) and skipped, never fatal."""

from __future__ import annotations

import threading

import pytest
from hypothesis import given
from hypothesis import strategies as st

from robofabric.soak.history import (
    KINDS,
    Cmd,
    Fault,
    Joints,
    Mark,
    OwnEvent,
    OwnRec,
    ProcExit,
    ProcSample,
    Writer,
    from_line,
    read,
    to_line,
)
from robofabric.soak.nemesis import Nemesis, parse_victims

t = st.floats(0, 1e6, allow_nan=False)
text = st.text(max_size=30)
names = st.text("abcdefgh0123456789-", min_size=1, max_size=10)
qs = st.lists(st.floats(-4, 4, allow_nan=False), max_size=7).map(tuple)
records = st.one_of(
    st.builds(
        OwnRec,
        t,
        names,
        names,
        st.integers(0, 10**6),
        st.lists(names, max_size=4).map(tuple),
        st.sampled_from(["still", "moving"]),
        names,
        st.integers(0, 99),
    ),
    st.builds(OwnEvent, t, names, names, names, text, names),
    st.builds(Cmd, t, names, names, st.integers(0, 10**6), names, qs),
    st.builds(Joints, t, names, qs, t, names, st.integers(0, 99)),
    st.builds(Fault, t, names, names, t, text),
    st.builds(
        ProcSample,
        t,
        names,
        st.integers(1, 10**6),
        st.floats(0, 1e5, allow_nan=False),
        st.integers(0, 999),
        st.integers(0, 999),
        st.integers(0, 10**9),
    ),
    st.builds(ProcExit, t, names, st.integers(1, 10**6), st.integers(-64, 255), st.booleans(), text),
    st.builds(Mark, t, names, text),
)


@given(records)
def test_every_record_survives_its_line(rec):
    assert from_line(to_line(rec)) == rec


def test_every_kind_has_a_record_type():
    assert set(KINDS) == {"own", "ev", "cmd", "rej", "joints", "fault", "proc", "exit", "mark"}


def test_files_read_back_in_time_order_and_bad_lines_are_named(tmp_path):
    a, b = tmp_path / "wire.jsonl", tmp_path / "soak.jsonl"
    with Writer(a) as w:
        w.write(Mark(3.0, "end"))
        w.write(Mark(1.0, "start"))
    b.write_text(
        to_line(Fault(2.0, "pause", "sim-a", 4.0))
        + "\n"
        + '{"k": "own", "t": 1\n'
        + '{"k": "nope", "t": 1}\n'
        + "[1]\n"
    )
    recs, bad = read([a, b, tmp_path / "missing.jsonl"])
    assert [r.t for r in recs] == [1.0, 2.0, 3.0]
    assert [x.split(":")[:2] for x in bad] == [["soak.jsonl", "2"], ["soak.jsonl", "3"], ["soak.jsonl", "4"]]


def test_a_writer_shared_by_threads_writes_whole_lines(tmp_path):
    path = tmp_path / "h.jsonl"
    with Writer(path) as w:
        threads = [
            threading.Thread(
                target=lambda i=i: [w.write(Mark(float(i * 1000 + k), "x", "y" * 200)) for k in range(200)]
            )
            for i in range(4)
        ]
        for th in threads:
            th.start()
        for th in threads:
            th.join()
    recs, bad = read([path])
    assert len(recs) == 800 and not bad


def test_the_nemesis_refuses_unknown_fault_kinds_and_victims():
    with pytest.raises(ValueError, match="unknown fault kinds"):
        Nemesis(None, print, seed=1, kinds=("pause", "flood"))  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="victims"):
        Nemesis(None, print, seed=1, victims=("router",))  # type: ignore[arg-type]


def test_victims_take_optional_weights_and_refuse_what_is_not_a_victim_or_a_weight():
    assert parse_victims("sim=0.25,compute, student") == {"sim": 0.25, "compute": 1.0, "student": 1.0}
    assert parse_victims("student") == {"student": 1.0}
    for bad in ("router", "sim=0", "sim=-1", "sim=x", "", "sim=1e9"):
        with pytest.raises(ValueError, match="expected some of"):
            parse_victims(bad)
