"""The teacher's page, its pure part (user_peer/console/teacher.py): who may open it, each robot's actions, the tables."""

from __future__ import annotations

import re

import pytest
from hypothesis import given, strategies as hs

from fabric.interfaces import STAFF_OPS, OwnershipRecord
from user_peer.console import teacher


def test_only_the_consoles_instructors_may_open_the_page_or_act():
    teacher.require_staff("carol", ("carol",))
    assert teacher.class_actions("carol", ["carol"]) == ("stop_all", "reset_world")
    for name, staff, words in (
        ("bob", ("carol",), "bob is not one of this console's"),
        ("", ("carol",), "nobody is not"),
        ("carol", (), re.escape("names none (robofabric console --instructors NAME)")),
    ):
        with pytest.raises(teacher.NotStaff, match=words):
            teacher.require_staff(name, staff)
        assert teacher.class_actions(name, staff) == ()
    with pytest.raises(teacher.NotStaff, match=r"^this action is for instructors"):
        teacher.require_staff("bob", ("carol",), what="this action")


def test_a_robots_row_offers_what_its_record_allows():
    assert teacher.robot_actions(OwnershipRecord("arm1")) == ("give", "lock", "stop", "reset")
    assert teacher.robot_actions(OwnershipRecord("arm1", owner="alice")) == (
        "take_back",
        "give",
        "lock",
        "stop",
        "reset",
    )
    assert teacher.robot_actions(OwnershipRecord("arm1", locked="carol")) == ("unlock", "stop", "reset")
    assert teacher.robot_actions(OwnershipRecord("ball", policy="scene")) == ()
    assert teacher.robot_actions(None) == ()
    assert set(teacher.LABELS) == set(STAFF_OPS)


def test_the_tables_rows():
    records = {
        "arm1": OwnershipRecord("arm1", owner="alice", queue=("bob",), state="moving", epoch=3),
        "base1": OwnershipRecord("base1", locked="carol", epoch=5),
    }
    rows = teacher.robot_rows({"base1": "mobile", "arm1": "arm", "arm2": "arm"}, records)
    assert [r.robot for r in rows] == ["arm1", "arm2", "base1"]
    assert rows[0] == teacher.RobotRow(
        "arm1", "arm", "alice", "bob", "moving", "", 3, ("take_back", "give", "lock", "stop", "reset")
    )
    assert rows[1].owner == "(no record yet)" and rows[1].actions == ()
    assert rows[2].owner == "(free)" and rows[2].locked == "carol" and rows[2].actions == ("unlock", "stop", "reset")
    people = teacher.student_rows({"alice": 2, "carol": 1}, ["alice", "dave", "carol"], records, ["carol"])
    assert [(p.name, p.role, p.pages, p.live, p.owns, p.waits) for p in people] == [
        ("alice", "student", 2, True, "arm1", "-"),
        ("bob", "student", 0, False, "-", "arm1"),
        ("dave", "student", 0, True, "-", "-"),
        ("carol", "instructor", 1, True, "-", "-"),
    ]


def test_a_name_from_the_network_is_one_line_and_capped():
    rec = OwnershipRecord("arm1", owner="eve\n\x1b[31m" + "x" * 200)
    row = teacher.robot_rows({"arm1": "arm"}, {"arm1": rec})[0]
    assert "\n" not in row.owner and "\x1b" not in row.owner and len(row.owner) <= 64


@given(
    hs.dictionaries(
        hs.sampled_from(["arm1", "arm2", "base1"]),
        hs.tuples(
            hs.sampled_from(["", "alice", "bob"]),
            hs.lists(hs.sampled_from(["alice", "bob", "dave"]), max_size=3, unique=True),
            hs.sampled_from(["", "carol"]),
        ),
    )
)
def test_every_owner_and_waiter_has_a_row_that_says_so(spec):
    records = {
        rid: OwnershipRecord(rid, owner="" if locked else owner, queue=tuple(q), locked=locked)
        for rid, (owner, q, locked) in spec.items()
    }
    people = {p.name: p for p in teacher.student_rows({}, [], records, ["carol"])}
    for rid, rec in records.items():
        if rec.owner:
            assert rid in people[rec.owner].owns.split(", ")
        for u in rec.queue:
            assert rid in people[u].waits.split(", ")
        acts = teacher.robot_actions(rec)
        assert ("unlock" in acts) == bool(rec.locked) and ("lock" in acts) != bool(rec.locked)
        assert ("take_back" in acts) == bool(rec.owner)


def test_an_instructors_login_card_names_the_page_where_the_console_serves_it():
    from robofabric.login_cards import teacher_url

    assert teacher_url("http://10.0.0.5:8080/") == "http://10.0.0.5:8080" + teacher.ROUTE
    assert teacher_url("https://console.example:8443") == "https://console.example:8443" + teacher.ROUTE
