"""Transport benchmark: 240-ray scans from one process to another through a router, side by side with MQTT.

``robofabric bench transport`` starts a router, then for each rate a subscriber
and a publisher, each in its own process (``python -m robofabric.bench.transport
pub|sub``), and reports delivered %, latency percentiles (header wall time to
receive wall time, one host clock) and bytes/s. With ``--mqtt`` and a
``mosquitto`` on PATH, the same workload runs through mosquitto with paho
(QoS 0) for comparison.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time
from typing import Annotated

import numpy as np
import typer

from robofabric.stats import percentiles
from robofabric.bench.common import TableOut, append

KEY = "rf/bench/robot/base1/scan"
TOPIC = "rf/bench/robot/base1/scan"
RAYS = 240


def _scan_payload(seq: int, rng: np.random.Generator, ranges: np.ndarray) -> bytes:
    from fabric.codec import encode
    from fabric.interfaces import Header, Scan

    h = Header(stamp=seq * 0.001, wall_ns=time.time_ns(), seq=seq, source="bench-pub")
    return encode(Scan(-1.178, 2.356 / (RAYS - 1), 12.0, ranges, h))


def _pace(rate: float, count: int, duration: float, send) -> int:
    """Send at ``rate`` on an absolute schedule (0 = flat out); return how many were sent."""
    rng = np.random.default_rng(1)
    ranges = (rng.random(RAYS) * 12000).astype(np.uint16)
    t0 = time.perf_counter()
    sent = 0
    while True:
        if rate > 0:
            if sent >= count:
                break
            due = t0 + sent / rate
            while True:
                d = due - time.perf_counter()
                if d <= 0:
                    break
                time.sleep(d if d > 0.002 else 0)
        elif time.perf_counter() - t0 >= duration:
            break
        send(_scan_payload(sent, rng, ranges))
        sent += 1
    return sent


# --------------------------------------------------------------------------- child processes


def _child_pub(a: argparse.Namespace) -> None:
    if a.transport == "zenoh":
        import zenoh

        from fabric.config import FabricConfig
        from fabric.session import Fabric

        fab = Fabric(
            FabricConfig(world="bench", connect=(a.endpoint,), config_file=a.zenoh_config),
            kind="tool",
            peer_id="bench-pub",
        )
        pub = fab.session.declare_publisher(
            KEY, congestion_control=zenoh.CongestionControl.BLOCK
        )  # raw: zenoh's own path is what is measured (payload bytes as given, no Fabric encode or stamp)
        time.sleep(0.5)  # route establishment before the first sample; the subscriber is already up
        sent = _pace(a.rate, a.count, a.duration, pub.put)
        time.sleep(0.3)
        pub.undeclare()
        fab.close()
    else:
        import paho.mqtt.client as mqtt

        host, port = a.endpoint.split(":")
        c = mqtt.Client(mqtt.CallbackAPIVersion.VERSION2, client_id="bench-pub")
        c.connect(host, int(port))
        c.loop_start()
        time.sleep(0.3)
        sent = _pace(a.rate, a.count, a.duration, lambda p: c.publish(TOPIC, p, qos=0))
        time.sleep(0.3)
        c.loop_stop()
        c.disconnect()
    print(json.dumps({"sent": sent}), flush=True)


def _child_sub(a: argparse.Namespace) -> None:
    lat: list[float] = []
    seqs: list[int] = []
    nbytes = [0]
    first_last = [0.0, 0.0]
    lock = threading.Lock()
    from fabric.codec import decode

    def on_payload(payload: bytes) -> None:
        now = time.time_ns()
        msg = decode(payload)
        with lock:
            lat.append((now - msg.header.wall_ns) / 1e6)
            seqs.append(msg.header.seq)
            nbytes[0] += len(payload)
            if first_last[0] == 0.0:
                first_last[0] = time.monotonic()
            first_last[1] = time.monotonic()

    if a.transport == "zenoh":
        from fabric.config import FabricConfig
        from fabric.session import Fabric

        fab = Fabric(
            FabricConfig(world="bench", connect=(a.endpoint,), config_file=a.zenoh_config),
            kind="tool",
            peer_id="bench-sub",
        )
        fab.subscribe_raw(KEY, lambda s: on_payload(s.payload.to_bytes()))
        closer = fab.close
    else:
        import paho.mqtt.client as mqtt

        host, port = a.endpoint.split(":")
        c = mqtt.Client(mqtt.CallbackAPIVersion.VERSION2, client_id="bench-sub")
        c.on_message = lambda _c, _u, m: on_payload(m.payload)
        c.connect(host, int(port))
        c.subscribe(TOPIC, qos=0)
        c.loop_start()

        def closer() -> None:
            c.loop_stop()
            c.disconnect()

    print("ready", flush=True)
    # Wait for the orchestrator to say how many were sent (stdin line), then for quiet.
    line = sys.stdin.readline()
    sent = json.loads(line)["sent"] if line.strip() else 0
    deadline = time.monotonic() + 5.0
    while time.monotonic() < deadline:
        with lock:
            if len(seqs) >= sent:
                break
        time.sleep(0.05)
    closer()
    with lock:
        span = first_last[1] - first_last[0]
        out = {
            "sent": sent,
            "received": len(seqs),
            "unique": len(set(seqs)),
            "bytes_per_s": nbytes[0] / span if span > 0 else 0.0,
            "bytes_per_msg": nbytes[0] / max(1, len(seqs)),
            **percentiles(lat, (50, 99, 100)),
        }
    print(json.dumps(out), flush=True)


# --------------------------------------------------------------------------- orchestrator


def _free_port() -> int:
    from robofabric.testing import free_port

    return free_port()


def run_one(
    transport: str,
    endpoint: str,
    rate: float,
    duration: float,
    *,
    pub_config: str | None = None,
    sub_config: str | None = None,
) -> dict:
    """One publisher/subscriber pair; ``pub_config``/``sub_config``: zenoh configs (credentials, TLS)."""
    count = int(rate * duration) if rate > 0 else 0
    me = [sys.executable, "-m", "robofabric.bench.transport"]
    common = ["--transport", transport, "--endpoint", endpoint]
    sub_args = ["--zenoh-config", sub_config] if sub_config else []
    pub_args = ["--zenoh-config", pub_config] if pub_config else []
    sub = subprocess.Popen(me + ["sub", *common, *sub_args], stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    try:
        assert sub.stdout is not None and sub.stdin is not None
        if sub.stdout.readline().strip() != "ready":
            raise RuntimeError("benchmark subscriber did not start")
        pub = subprocess.run(
            me + ["pub", *common, *pub_args, "--rate", str(rate), "--count", str(count), "--duration", str(duration)],
            capture_output=True,
            text=True,
            timeout=duration * 3 + 30,
        )
        if pub.returncode != 0:
            raise RuntimeError(f"benchmark publisher failed: {pub.stderr.strip()[-500:]}")
        sent = json.loads(pub.stdout.strip().splitlines()[-1])["sent"]
        sub.stdin.write(json.dumps({"sent": sent}) + "\n")
        sub.stdin.flush()
        result = json.loads(sub.stdout.readline())
    finally:
        if sub.poll() is None:
            sub.wait(timeout=15)
    result["delivered_pct"] = 100.0 * result["unique"] / max(1, result["sent"])
    result["rate"] = rate
    result["transport"] = transport
    return result


def wait_listening(port: int, proc: subprocess.Popen, timeout: float = 60.0) -> None:
    """Until the router child accepts connections on ``port`` (its start takes seconds on a loaded machine)."""
    import socket

    deadline = time.monotonic() + timeout
    while True:
        try:
            with socket.create_connection(("127.0.0.1", port), timeout=1.0):
                return
        except OSError:
            if proc.poll() is not None or time.monotonic() > deadline:
                raise RuntimeError(
                    f"the benchmark router did not listen on port {port} within {timeout:.0f} s"
                ) from None
            time.sleep(0.1)


def run_bench(rates: list[float], duration: float, mqtt: bool) -> list[dict]:
    results: list[dict] = []
    port = _free_port()
    router = subprocess.Popen(
        [sys.executable, "-m", "robofabric.cli", "router", "--listen", f"tcp/127.0.0.1:{port}", "--world", "bench"],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        start_new_session=True,
    )
    broker = None
    tmp = None
    try:
        wait_listening(port, router)
        for r in rates:
            results.append(run_one("zenoh", f"tcp/127.0.0.1:{port}", r, duration))
        if mqtt:
            exe = shutil.which("mosquitto") or (
                "/usr/sbin/mosquitto" if os.path.exists("/usr/sbin/mosquitto") else None
            )
            if exe is None:
                print("mosquitto not found on PATH: MQTT comparison skipped", file=sys.stderr)
            else:
                mport = _free_port()
                tmp = tempfile.NamedTemporaryFile("w", suffix=".conf", delete=False)
                tmp.write(f"listener {mport} 127.0.0.1\nallow_anonymous true\nmax_queued_messages 100000\n")
                tmp.close()
                broker = subprocess.Popen([exe, "-c", tmp.name], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
                time.sleep(0.5)
                for r in rates:
                    results.append(run_one("mqtt", f"127.0.0.1:{mport}", r, duration))
    finally:
        for p in (router, broker):
            if p is not None and p.poll() is None:
                p.send_signal(signal.SIGTERM)
                try:
                    p.wait(timeout=5)
                except subprocess.TimeoutExpired:
                    p.kill()
        if tmp is not None:
            os.unlink(tmp.name)
    return results


def format_table(results: list[dict]) -> str:
    lines = [
        "| transport | rate (Hz) | sent | delivered % | p50 (ms) | p99 (ms) | max (ms) | bytes/msg | kB/s |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for r in results:
        rate = "flat out" if r["rate"] == 0 else f"{r['rate']:.0f}"
        lines.append(
            f"| {r['transport']} | {rate} | {r['sent']} | {r['delivered_pct']:.2f} | {r['p50']:.3f} | {r['p99']:.3f} | "
            f"{r['p100']:.3f} | {r['bytes_per_msg']:.0f} | {r['bytes_per_s'] / 1000:.1f} |"
        )
    return "\n".join(lines)


def command(
    rates: Annotated[str, typer.Option(help="Comma-separated rates in Hz; 0 means flat out.")] = "20,100,1000,0",
    duration: Annotated[float, typer.Option(help="Seconds per rate.")] = 5.0,
    mqtt: Annotated[bool, typer.Option("--mqtt/--no-mqtt", help="Also run through mosquitto + paho (QoS 0).")] = True,
    as_json: Annotated[bool, typer.Option("--json")] = False,
    out: TableOut = None,
) -> None:
    """240-ray scans, publisher and subscriber in separate processes through a router on loopback."""
    from fabric.cli_common import UserError

    try:
        rate_list = [float(x) for x in rates.split(",") if x.strip()]
    except ValueError:
        raise UserError(f"--rates {rates!r}: expected numbers like 20,100,1000,0") from None
    if not rate_list or any(r < 0 for r in rate_list) or duration <= 0:
        raise UserError("--rates must be non-negative numbers and --duration positive")
    results = run_bench(rate_list, duration, mqtt)
    if as_json:
        print(json.dumps(results))
        return
    table = format_table(results)
    print(table)
    append(out, table)


def _main() -> None:
    ap = argparse.ArgumentParser(prog="python -m robofabric.bench.transport")
    ap.add_argument("role", choices=("pub", "sub"))
    ap.add_argument("--transport", choices=("zenoh", "mqtt"), default="zenoh")
    ap.add_argument("--endpoint", required=True)
    ap.add_argument("--rate", type=float, default=1000.0)
    ap.add_argument("--count", type=int, default=1000)
    ap.add_argument("--duration", type=float, default=3.0)
    ap.add_argument("--zenoh-config", default=None, help="zenoh config file (credentials, TLS) for this side")
    a = ap.parse_args()
    (_child_pub if a.role == "pub" else _child_sub)(a)


if __name__ == "__main__":
    _main()
