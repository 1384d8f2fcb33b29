"""The tests' free ports (tests/loopback.py): below the kernel's ephemeral range, so that no outgoing
connection takes one between its pick and its bind."""

from __future__ import annotations

import socket

from tests.loopback import SPAN, _ephemeral_low, free_port


def test_free_ports_are_below_the_ephemeral_range_and_bindable() -> None:
    low = _ephemeral_low()
    ports = [free_port() for _ in range(20)]
    assert all(low - SPAN <= p < low for p in ports), (low, ports)
    for port in ports:
        with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
            s.bind(("127.0.0.1", port))


def test_a_port_in_use_is_never_picked() -> None:
    held = []
    try:
        for _ in range(200):
            s = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
            s.bind(("127.0.0.1", free_port()))
            s.listen()
            held.append(s)
        assert len({s.getsockname()[1] for s in held}) == 200
    finally:
        for s in held:
            s.close()
