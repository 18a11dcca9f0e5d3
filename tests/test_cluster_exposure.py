"""The exposure report of ``sray cluster status`` on sockets whose binding the test chooses."""

from __future__ import annotations

import subprocess
import sys
import time

from sray.platform.cluster.exposure import Listener, exposure_line, listeners

BIND = """
import socket, sys, time
ports = []
for host in ("127.0.0.1", "0.0.0.0"):
    s = socket.socket(); s.bind((host, 0)); s.listen(); ports.append(s.getsockname()[1])
    globals()[f"keep_{host}"] = s
print(*ports, flush=True)
time.sleep(60)
"""


def test_loopback_and_wildcard_sockets_are_told_apart() -> None:
    child = subprocess.Popen([sys.executable, "-c", BIND], stdout=subprocess.PIPE, text=True)
    try:
        loop_port, any_port = map(int, child.stdout.readline().split())
        deadline = time.monotonic() + 10
        while len(found := listeners({"probe": child.pid})) < 2 and time.monotonic() < deadline:
            time.sleep(0.1)
        assert {(x.port, x.loopback_only) for x in found} == {(loop_port, True), (any_port, False)}
        assert all(x.part == "probe" and x.pid == child.pid for x in found)
        line = exposure_line(found)
        assert f"0.0.0.0:{any_port}" in line and f":{loop_port}" not in line and "1 of 2" in line
        assert exposure_line([x for x in found if x.loopback_only]).endswith("all 1 listening ports are on "
                                                                             "loopback only")
    finally:
        child.kill()
        child.wait()
    assert listeners({"gone": child.pid}) == []


def test_ipv4_mapped_loopback_counts_as_loopback() -> None:
    assert Listener("p", "x", 1, "::ffff:127.0.0.1", 80).loopback_only
    assert not Listener("p", "x", 1, "::ffff:192.0.2.2", 80).loopback_only
    assert not Listener("p", "x", 1, "::", 80).loopback_only and Listener("p", "x", 1, "::1", 80).loopback_only
