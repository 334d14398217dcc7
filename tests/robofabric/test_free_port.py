"""free_port deals loopback ports under the kernel's ephemeral range, one slice per xdist worker."""

from __future__ import annotations

import socket

from robofabric.testing import PORTS_BELOW_EPHEMERAL, free_port, port_slice


def test_each_worker_has_its_own_slice_under_the_ephemeral_range_and_others_the_last():
    low = 32768
    slices = [
        port_slice({"PYTEST_XDIST_WORKER": f"gw{i}", "PYTEST_XDIST_WORKER_COUNT": "4"}, ephemeral_low=low)
        for i in range(4)
    ]
    outside = port_slice({}, ephemeral_low=low)  # a process outside the workers (count 0: the whole range)
    assert outside == (low - PORTS_BELOW_EPHEMERAL, PORTS_BELOW_EPHEMERAL)
    last = port_slice({"PYTEST_XDIST_WORKER_COUNT": "4"}, ephemeral_low=low)  # a worker's child: no worker id
    ranges = [set(range(a, a + n)) for a, n in [*slices, last]]
    assert all(n == PORTS_BELOW_EPHEMERAL // 5 for _, n in [*slices, last])
    assert all(not (ranges[i] & ranges[j]) for i in range(5) for j in range(i + 1, 5))  # no two share a port
    assert min(min(r) for r in ranges) >= low - PORTS_BELOW_EPHEMERAL and max(max(r) for r in ranges) < low


def test_free_port_hands_out_bindable_ports_below_the_ephemeral_range_never_twice():
    first, size = port_slice()
    ports = [free_port() for _ in range(50)]
    assert len(set(ports)) == 50 and all(first <= p < first + size for p in ports), (first, size, ports)
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", ports[-1]))  # free now
