"""``robofabric bench paper``: the paper's data-usage tables (Tables 2-3) measured side by side.

For zenoh (through a robofabric router) and for MQTT (mosquitto, paho, QoS 0), at each rate and for each
payload, a publisher process streams for ``--duration`` seconds to a subscriber process through the broker.
The publisher reaches the broker through a :class:`~robofabric.bench.wire.CountingProxy`, which counts the
TCP stream bytes and segments it sends: payload bytes, stream bytes and wire bytes (stream plus Ethernet,
IPv4 and TCP headers per segment) per message, and MB per minute from windows of ``--window`` seconds
(max, avg, min, each window scaled to a minute) and GB per hour from the average.

Payloads:

- ``paper-135``: the closest honest equivalent of the paper's reduced scan. The paper sent 415 "data points"
  a message for 135 rays as JSON (it names no schema): here a JSON object of 415 numbers, 135 rays of hit
  (x, y) and range (405) plus time, sequence, ray count and the pose (x, y, z, quaternion), each number
  with float32's 7 significant digits as Unity writes them. The paper sent it through Firebase's REST API
  (HTTP over TLS), which this does not reproduce: its figures stand beside ours as published.
- ``rf-240``: robofabric's own 240-ray :class:`~fabric.interfaces.Scan` (uint16 millimetres), as the sim sends.
- ``arm-joints``: the Meca500's :class:`~fabric.interfaces.JointState` (6 names, q, dq, header).

``--resources`` adds the paper's Table 4 for robofabric (:mod:`robofabric.bench.paper_resources`), and
``--multi-user`` its 5-user test for ``--minutes`` (:mod:`robofabric.bench.paper_multi`): each student's delay
on the robots she does not own. ``--no-data-usage`` leaves the data-usage tables out, so the sections of one
full run can be taken apart. The ``--json`` document: ``data_usage``, ``resources``, ``multi_user`` (each when
run), ``paper`` (the published figures), ``machine`` and the load average at its start and end.
"""

from __future__ import annotations

import argparse
import json
import math
import shutil
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Annotated, Callable, Optional

import typer

from robofabric.bench.common import TablesOut, append, end_process, machine

__all__ = ["PAYLOADS", "RATES", "make_payload", "run_bench", "format_table", "command"]

KEY = "rf/bench/paper/stream"
RATES = (10, 20, 50, 100, 200, 600)
PAYLOADS = ("paper-135", "rf-240", "arm-joints")
VARIANTS = 16  # distinct scans cycled through (their text lengths vary like real ones); built before timing


# --------------------------------------------------------------------------- payloads


def _paper_json(seq: int, variant: int) -> bytes:
    import numpy as np

    rng = np.random.default_rng(variant)
    ranges = rng.uniform(0.2, 12.0, 135).astype(np.float32)
    ang = np.deg2rad(np.arange(135, dtype=np.float32) - 67.0)
    pose = rng.uniform(-5, 5, 3).tolist() + [0.0, 0.0, float(np.sin(variant)), float(np.cos(variant))]
    g = lambda v: float(f"{float(v):.7g}")  # noqa: E731  float32 text, as Unity's JSON writes it
    rays = [[g(r * math.cos(a)), g(r * math.sin(a)), g(r)] for r, a in zip(ranges, ang)]
    doc = {"t": g(seq * 0.05 + 0.0123), "seq": seq, "n": 135, "pose": [g(v) for v in pose], "rays": rays}
    return json.dumps(doc, separators=(",", ":")).encode()


def _rf_scan(seq: int, variant: int) -> bytes:
    import numpy as np

    from fabric.codec import encode
    from fabric.interfaces import Header, Scan

    ranges = (np.random.default_rng(variant).random(240) * 12000).astype(np.uint16)
    return encode(
        Scan(
            -1.178,
            2.356 / 239,
            12.0,
            ranges,
            Header(stamp=seq * 0.05, wall_ns=time.time_ns(), seq=seq, source="bench-pub"),
        )
    )


def _arm_joints(seq: int, variant: int) -> bytes:
    import numpy as np

    from fabric.codec import encode
    from fabric.interfaces import Header, JointState

    rng = np.random.default_rng(variant)
    return encode(
        JointState(
            tuple(f"j{i}" for i in range(1, 7)),
            rng.uniform(-2, 2, 6),
            rng.uniform(-1, 1, 6),
            Header(stamp=seq * 0.05, wall_ns=time.time_ns(), seq=seq, source="bench-pub"),
        )
    )


_MAKERS: dict[str, Callable[[int, int], bytes]] = {
    "paper-135": _paper_json,
    "rf-240": _rf_scan,
    "arm-joints": _arm_joints,
}


def make_payload(name: str, seq: int = 0) -> bytes:
    """One message of payload ``name`` (one of :data:`PAYLOADS`)."""
    return _MAKERS[name](seq, seq % VARIANTS)


def count_numbers(payload: bytes) -> int:
    """How many numbers a ``paper-135`` message carries (the paper's "data points"): 415."""
    doc = json.loads(payload)
    return 3 + len(doc["pose"]) + sum(len(r) for r in doc["rays"])


# --------------------------------------------------------------------------- child processes


def _child_pub(a: argparse.Namespace) -> None:
    msgs = [make_payload(a.payload, i) for i in range(VARIANTS)]  # built before the clock starts
    if a.transport == "zenoh":
        import zenoh

        from fabric.config import FabricConfig
        from fabric.session import Fabric

        fab = Fabric(FabricConfig(world="bench", connect=(a.endpoint,)), kind="tool", peer_id="bench-pub")
        pub = fab.session.declare_publisher(
            KEY, congestion_control=zenoh.CongestionControl.BLOCK
        )  # raw: zenoh's own path is what is measured (payload bytes as given, no Fabric encode or stamp)
        deadline = time.monotonic() + 10.0
        while time.monotonic() < deadline and not pub.matching_status.matching:
            time.sleep(0.02)
        send: Callable[[bytes], object] = pub.put

        def close() -> None:
            pub.undeclare()
            fab.close()
    else:
        import paho.mqtt.client as mqtt

        host, port = a.endpoint.split(":")
        c = mqtt.Client(mqtt.CallbackAPIVersion.VERSION2, client_id="bench-paper-pub")
        c.connect(host, int(port))
        c.loop_start()
        time.sleep(0.3)  # CONNACK
        send = lambda p: c.publish(KEY, p, qos=0)  # noqa: E731

        def close() -> None:
            c.loop_stop()
            c.disconnect()

    payload_bytes = 0
    n = max(1, round(a.rate * a.duration))
    print("ready", flush=True)
    sys.stdin.readline()  # "go": the orchestrator has taken its first count, so every message falls inside
    t0 = time.perf_counter()
    for i in range(n):
        due = t0 + i / a.rate
        while (d := due - time.perf_counter()) > 0:
            time.sleep(d if d > 0.002 else 0)
        m = msgs[i % VARIANTS]
        send(m)
        payload_bytes += len(m)
    time.sleep(0.2)  # let the last batch leave before the orchestrator's final count
    print(json.dumps({"sent": n, "payload_bytes": payload_bytes, "seconds": time.perf_counter() - t0}), flush=True)
    sys.stdin.readline()  # the orchestrator has counted: close
    close()


def _child_sub(a: argparse.Namespace) -> None:
    got = [0, 0]
    lock = threading.Lock()

    def on(payload: bytes) -> None:
        with lock:
            got[0] += 1
            got[1] += len(payload)

    if a.transport == "zenoh":
        from fabric.config import FabricConfig
        from fabric.session import Fabric

        fab = Fabric(FabricConfig(world="bench", connect=(a.endpoint,)), kind="tool", peer_id="bench-sub")
        fab.subscribe_raw(KEY, lambda s: on(s.payload.to_bytes()))
        closer = fab.close
    else:
        import paho.mqtt.client as mqtt

        host, port = a.endpoint.split(":")
        subscribed = threading.Event()
        c = mqtt.Client(mqtt.CallbackAPIVersion.VERSION2, client_id="bench-paper-sub")
        c.on_message = lambda _c, _u, m: on(m.payload)
        c.on_subscribe = lambda *_: subscribed.set()
        c.connect(host, int(port))
        c.subscribe(KEY, qos=0)
        c.loop_start()
        subscribed.wait(10.0)

        def closer() -> None:
            c.loop_stop()
            c.disconnect()

    print("ready", flush=True)
    line = sys.stdin.readline()
    sent = json.loads(line)["sent"] if line.strip() else 0
    deadline = time.monotonic() + 5.0
    while time.monotonic() < deadline:
        with lock:
            if got[0] >= sent:
                break
        time.sleep(0.05)
    closer()
    with lock:
        print(json.dumps({"received": got[0], "received_bytes": got[1]}), flush=True)


# --------------------------------------------------------------------------- orchestrator


def _start_broker(transport: str, tmpdir: str) -> tuple[subprocess.Popen, int]:
    from robofabric.testing import free_port, robofabric_cmd
    from robofabric.bench.transport import wait_listening

    port = free_port()
    if transport == "zenoh":
        argv = robofabric_cmd("router", "--listen", f"tcp/127.0.0.1:{port}", "--world", "bench")
    else:
        exe = shutil.which("mosquitto") or shutil.which("/usr/sbin/mosquitto")
        if exe is None:
            raise RuntimeError("mosquitto is not on PATH (apt-get install mosquitto): the MQTT side cannot run")
        conf = Path(tmpdir) / "mosquitto.conf"
        conf.write_text(f"listener {port} 127.0.0.1\nallow_anonymous true\nmax_queued_messages 100000\n")
        argv = [exe, "-c", str(conf)]
    proc = subprocess.Popen(argv, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        wait_listening(port, proc)
    except Exception:
        end_process(proc)
        raise
    return proc, port


def _window_stats(samples: list[float]) -> tuple[float, float, float]:
    """(max, avg, min) of per-window MB/min; NaN for none."""
    if not samples:
        return (math.nan, math.nan, math.nan)
    return (max(samples), sum(samples) / len(samples), min(samples))


def run_one(transport: str, broker_port: int, rate: float, payload: str, duration: float, window: float) -> dict:
    """One publisher (through a counting proxy) and one subscriber (straight to the broker); one row."""
    from robofabric.bench.wire import CountingProxy, ethernet_segments

    me = [sys.executable, "-m", "robofabric.bench.paper"]
    endpoint = (lambda p: f"tcp/127.0.0.1:{p}") if transport == "zenoh" else (lambda p: f"127.0.0.1:{p}")
    common = ["--transport", transport, "--payload", payload, "--rate", str(rate), "--duration", str(duration)]
    sub = subprocess.Popen(
        me + ["sub", *common, "--endpoint", endpoint(broker_port)],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        text=True,
    )
    proxy = CountingProxy(("127.0.0.1", broker_port))
    pub: subprocess.Popen | None = None
    try:
        assert sub.stdout is not None and sub.stdin is not None
        if sub.stdout.readline().strip() != "ready":
            raise RuntimeError(f"the {transport} subscriber did not start")
        pub = subprocess.Popen(
            me + ["pub", *common, "--endpoint", endpoint(proxy.port)],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            text=True,
        )
        assert pub.stdout is not None and pub.stdin is not None
        if pub.stdout.readline().strip() != "ready":
            raise RuntimeError(f"the {transport} publisher did not start")
        marks = [proxy.count()]
        pub.stdin.write("go\n")
        pub.stdin.flush()
        t0 = time.monotonic()
        for k in range(1, int(duration / window + 1e-9) + 1):
            time.sleep(max(0.0, t0 + k * window - time.monotonic()))
            marks.append(proxy.count())
        done = json.loads(pub.stdout.readline())
        final = proxy.count()
        pub.stdin.write("\n")
        pub.stdin.flush()
        pub.wait(timeout=30)
        sub.stdin.write(json.dumps({"sent": done["sent"]}) + "\n")
        sub.stdin.flush()
        got = json.loads(sub.stdout.readline())
        sub.wait(timeout=30)
    finally:
        proxy.close()
        for p in (pub, sub):
            if p is not None and p.poll() is None:
                end_process(p)
    per_min = [(b - a).wire_bytes / window * 60 / 1e6 for a, b in zip(marks, marks[1:])]
    mx, avg, mn = _window_stats(per_min)
    total = final - marks[0]
    sent = done["sent"]
    payload_per_msg = done["payload_bytes"] / sent
    stream_per_msg = total.stream_bytes / sent
    return {
        "transport": transport,
        "rate_hz": rate,
        "payload": payload,
        "sent": sent,
        "received": got["received"],
        "payload_bytes_per_msg": payload_per_msg,
        "received_bytes_per_msg": got["received_bytes"] / max(1, got["received"]),
        "stream_bytes_per_msg": stream_per_msg,
        "segments_per_msg": total.segments / sent,
        "wire_bytes_per_msg": total.wire_bytes / sent,
        "ethernet_min_segments_per_msg": ethernet_segments(stream_per_msg),
        "windows": len(per_min),
        "window_s": window,
        "mb_per_min_max": mx,
        "mb_per_min_avg": avg,
        "mb_per_min_min": mn,
        "gb_per_hour": avg * 60 / 1e3,
    }


def run_bench(
    transports: list[str],
    rates: list[float],
    payloads: list[str],
    duration: float,
    window: float,
    progress: Callable[[str], None] = lambda s: print(s, file=sys.stderr, flush=True),
) -> list[dict]:
    """Every (transport, rate, payload) row, one broker per transport."""
    rows: list[dict] = []
    with tempfile.TemporaryDirectory(prefix="bench-paper-") as tmp:
        for transport in transports:
            broker, port = _start_broker(transport, tmp)
            try:
                for rate in rates:
                    for payload in payloads:
                        progress(f"{transport} {rate:g} Hz {payload}")
                        rows.append(run_one(transport, port, rate, payload, duration, window))
            finally:
                end_process(broker)
    return rows


def format_table(rows: list[dict]) -> str:
    from robofabric.bench.paper_figures import paper_rows

    lines = [
        "| transport | rate (Hz) | payload | payload B/msg | stream B/msg | wire B/msg | MB/min max | avg | min | GB/h |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(
            f"| {r['transport']} | {r['rate_hz']:g} | {r['payload']} | {r['payload_bytes_per_msg']:.0f} | "
            f"{r['stream_bytes_per_msg']:.0f} | {r['wire_bytes_per_msg']:.0f} | {r['mb_per_min_max']:.3f} | "
            f"{r['mb_per_min_avg']:.3f} | {r['mb_per_min_min']:.3f} | {r['gb_per_hour']:.4f} |"
        )
    lines += [
        "",
        "The paper's published figures (Firebase REST; MB = 10^6 bytes; B/msg implied = avg / (rate x 60)):",
        "",
        "| source | rate (Hz) | payload | B/msg implied | MB/min max | avg | min | GB/h |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for p in paper_rows():
        lines.append(
            f"| {p['source']} | {p['rate_hz']} | {p['payload']} | {p['bytes_per_msg_implied']} | {p['mb_per_min_max']} | "
            f"{p['mb_per_min_avg']} | {p['mb_per_min_min']} | {p['gb_per_hour']} |"
        )
    return "\n".join(lines)


def format_resources(rows: list[dict]) -> str:
    """Table 4's shape: each application's CPU (% of one core) and RSS, min and max while Test A and B ran."""
    lines = [
        "| application | CPU min % | CPU max % | RSS min (MB) | RSS max (MB) | seconds sampled |",
        "|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(
            f"| {r['peer']} | {r['cpu_min']:.1f} | {r['cpu_max']:.1f} | {r['rss_min_mb']:.0f} | {r['rss_max_mb']:.0f} | {r['samples']} |"
        )
    return "\n".join(lines)


def _parse_list(text: str, option: str, conv: Callable[[str], object], allowed: tuple | None = None) -> list:
    from fabric.cli_common import UserError

    try:
        items = [conv(x.strip()) for x in text.split(",") if x.strip()]
    except ValueError:
        raise UserError(f"{option} {text!r}: expected a comma-separated list") from None
    if not items or (allowed is not None and any(i not in allowed for i in items)):
        raise UserError(f"{option} {text!r}: expected a comma-separated list of {', '.join(map(str, allowed or ()))}")
    return items


def command(
    quick: Annotated[
        bool,
        typer.Option(
            "--quick",
            help="2 s per rate, 0.5 s windows, a 1-minute multi-user test (a smoke run); the full run is 60 s per rate, 1 s windows, 10 minutes.",
        ),
    ] = False,
    rates: Annotated[str, typer.Option(help="Comma-separated rates in Hz.")] = ",".join(map(str, RATES)),
    payloads: Annotated[str, typer.Option(help=f"Comma-separated payloads: {', '.join(PAYLOADS)}.")] = ",".join(
        PAYLOADS
    ),
    transports: Annotated[str, typer.Option(help="Comma-separated: zenoh, mqtt.")] = "zenoh,mqtt",
    duration: Annotated[Optional[float], typer.Option(help="Seconds per rate (default 60, or 2 with --quick).")] = None,
    window: Annotated[
        Optional[float], typer.Option(help="Seconds per MB/min sample (default 1, or 0.5 with --quick).")
    ] = None,
    as_json: Annotated[
        bool,
        typer.Option(
            "--json",
            help='One JSON document: {"data_usage", "resources", "multi_user" (each when run), "paper", "machine", "load_average"}.',
        ),
    ] = False,
    out: TablesOut = None,
    plot: Annotated[
        Optional[Path],
        typer.Option(help="Also draw MB/min against rate beside the paper's (SVG/PNG; needs matplotlib)."),
    ] = None,
    data_usage: Annotated[
        bool, typer.Option("--data-usage/--no-data-usage", help="The data-usage tables (Tables 2-3).")
    ] = True,
    resources: Annotated[
        bool,
        typer.Option(
            "--resources/--no-resources",
            help="Also Table 4: CPU and RSS of router, sim, compute, viewer, console and the users while Test A and Test B run (about 2 min).",
        ),
    ] = False,
    multi_user: Annotated[
        bool,
        typer.Option(
            "--multi-user/--no-multi-user",
            help="Also the paper's multi-user test: --students processes, each owning an arm and a base, for --minutes; the delay of the poses of robots each does not own.",
        ),
    ] = False,
    minutes: Annotated[
        Optional[float], typer.Option(help="Minutes of the multi-user test (default 10, or 1 with --quick).")
    ] = None,
    students: Annotated[int, typer.Option(help="Students in the multi-user test (the paper's: 5).")] = 5,
) -> None:
    """The paper's evaluation side by side: data usage (zenoh and MQTT at 10-600 Hz, the paper's 135-ray JSON
    scan, robofabric's 240-ray scan and the arm's joints; payload, stream and wire bytes per message from a
    counting TCP proxy, MB per minute max/avg/min and GB per hour, beside Tables 2-3), with --resources Table 4
    (CPU and RSS per application) and with --multi-user its 5-user test (delay on robots a user does not own)."""
    from fabric.cli_common import UserError
    from robofabric.bench.paper_figures import PAPER

    rate_list = _parse_list(rates, "--rates", float)
    payload_list = _parse_list(payloads, "--payloads", str, PAYLOADS)
    transport_list = _parse_list(transports, "--transports", str, ("zenoh", "mqtt"))
    duration = duration if duration is not None else (2.0 if quick else 60.0)
    window = window if window is not None else (0.5 if quick else 1.0)
    minutes = minutes if minutes is not None else (1.0 if quick else 10.0)
    if any(r <= 0 for r in rate_list) or duration <= 0 or window <= 0 or window > duration:
        raise UserError("--rates and --duration must be positive, and --window positive and at most --duration")
    if minutes <= 0 or students < 2:
        raise UserError(f"--minutes must be positive and --students at least 2 (got {minutes:g} and {students})")
    if not (data_usage or resources or multi_user):
        raise UserError("nothing to run: --no-data-usage needs --resources or --multi-user")
    if plot is not None and not data_usage:
        raise UserError("--plot draws the data-usage tables: it needs --data-usage")
    doc = _run_sections(
        (transport_list, rate_list, payload_list, duration, window) if data_usage else None,
        resources,
        (minutes, students) if multi_user else None,
    )
    doc["paper"] = PAPER
    if plot is not None:
        from robofabric.bench.paper_plot import plot as draw

        draw(doc, plot)
    if as_json:
        print(json.dumps(doc))
        return
    table = _format_doc(doc)
    print(table)
    append(out, table)


def _run_sections(data: tuple | None, resources: bool, multi: tuple | None) -> dict:
    """The sections asked for, one after the other (never two at once: each would load the other's figures)."""
    import os

    doc: dict = {"machine": machine(), "load_average": {"start": round(os.getloadavg()[0], 1)}}
    if data is not None:
        transports, rates, payloads, duration, window = data
        doc.update(
            duration_s=duration, window_s=window, data_usage=run_bench(transports, rates, payloads, duration, window)
        )
    if resources:
        from robofabric.bench.paper_resources import measure_resources

        res = measure_resources()
        doc["resources"] = res["rows"]
        doc["resources_run"] = {k: v for k, v in res.items() if k != "rows"}
    if multi is not None:
        from robofabric.bench.paper_multi import measure_multi_user

        minutes, students = multi
        doc["multi_user"] = measure_multi_user(minutes, students)
    doc["load_average"]["end"] = round(os.getloadavg()[0], 1)
    return doc


def _format_doc(doc: dict) -> str:
    parts = []
    if "data_usage" in doc:
        parts.append(format_table(doc["data_usage"]))
    if "resources" in doc:
        parts.append(format_resources(doc["resources"]))
    if "multi_user" in doc:
        from robofabric.bench.paper_multi import format_multi_user

        parts.append(format_multi_user(doc["multi_user"]))
    parts.append(
        f"Machine: {doc['machine']}; load average {doc['load_average']['start']} at the start, {doc['load_average']['end']} at the end"
    )
    return "\n\n".join(parts)


def _main() -> None:
    ap = argparse.ArgumentParser(prog="python -m robofabric.bench.paper")
    ap.add_argument("role", choices=("pub", "sub"))
    ap.add_argument("--transport", choices=("zenoh", "mqtt"), required=True)
    ap.add_argument("--endpoint", required=True)
    ap.add_argument("--payload", choices=PAYLOADS, required=True)
    ap.add_argument("--rate", type=float, required=True)
    ap.add_argument("--duration", type=float, required=True)
    a = ap.parse_args()
    (_child_pub if a.role == "pub" else _child_sub)(a)


if __name__ == "__main__":
    _main()
