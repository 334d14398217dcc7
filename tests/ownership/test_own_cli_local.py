"""``robofabric own list`` and ``watch`` print from the client's locked copy of its replica, never the live dict.

No session: the client is stood in by one that offers only the public read side (``snapshot``), as
OwnershipClient does since its replica is private (Zenoh's threads write it)."""

from __future__ import annotations

import json
import threading

import pytest

from fabric.interfaces import OwnershipRecord
from ownership import cli


class _Fabric:
    world = "w"

    def __enter__(self) -> "_Fabric":
        return self

    def __exit__(self, *exc: object) -> None:
        pass


class _Client:
    """Only what OwnershipClient offers publicly for reading records."""

    def __init__(self, records: dict[str, OwnershipRecord]) -> None:
        self._records = records
        self.snapshots = 0
        self.changes: list = []
        self.closed = False

    def snapshot(self) -> dict[str, OwnershipRecord]:
        self.snapshots += 1
        return dict(self._records)

    def on_change(self, cb) -> None:
        self.changes.append(cb)

    def close(self) -> None:
        self.closed = True


@pytest.fixture
def client(monkeypatch):
    c = _Client({"ball": OwnershipRecord("ball", policy="scene"), "arm": OwnershipRecord("arm", owner="ann", epoch=3)})
    monkeypatch.setattr(cli, "_client", lambda *a: (_Fabric(), c))
    return c


def test_list_prints_every_record_of_one_snapshot(client, capsys):
    cli.list_cmd(as_json=True)
    doc = json.loads(capsys.readouterr().out)  # one JSON document
    assert doc["world"] == "w" and set(doc["records"][0]) == {
        "object",
        "policy",
        "owner",
        "epoch",
        "queue",
        "state",
        "authority",
        "locked",
    }
    assert [(r["object"], r["owner"], r["epoch"]) for r in doc["records"]] == [("arm", "ann", 3), ("ball", "", 0)]
    assert client.snapshots == 1 and client.closed


def test_list_table_fits_a_narrow_terminal(client, capsys, monkeypatch):
    monkeypatch.setenv("COLUMNS", "60")
    cli.list_cmd()
    out = capsys.readouterr().out
    assert "ann" in out and "anyone" in out and "exclusive" in out
    assert max(len(line) for line in out.splitlines()) <= 60, out


def test_watch_starts_from_one_snapshot(client, capsys, monkeypatch):
    stop = threading.Event()
    stop.set()
    import fabric.session

    monkeypatch.setattr(fabric.session, "shutdown_event", lambda: stop)  # the command imports it when it runs
    cli.watch_cmd()
    out = capsys.readouterr().out.splitlines()
    assert [line.split()[0] for line in out] == ["arm", "ball"] and "owner ann" in out[0]
    assert client.snapshots == 1 and len(client.changes) == 1 and client.closed


def test_list_without_records_says_no_authority_answered(monkeypatch):
    monkeypatch.setattr(cli, "_client", lambda *a: (_Fabric(), _Client({})))
    monkeypatch.setattr(cli, "RECORDS_WAIT_S", 0.2)  # its wait for records, not the 5 s a terminal user gets
    with pytest.raises(cli.NothingThere, match="no ownership authority answered"):  # exit 1: the world had nothing
        cli.list_cmd()


def test_names_from_the_network_reach_the_terminal_escaped():
    rec = OwnershipRecord("arm\x1b[2J", owner="ann\x07", epoch=1, queue=("b\x1b]0;x\x07",))
    line = cli.record_line(rec)
    assert "\x1b" not in line and "\x07" not in line and "arm\\x1b[2J" in line and "ann\\x07" in line
