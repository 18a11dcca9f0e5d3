"""``check_ray_address``: a wrong ``--address`` is named in one line within seconds, whatever is (or is not)
listening there. The token refusal itself is checked against a real cluster in ``test_cluster.py``."""

from __future__ import annotations

import socket
import time

import pytest

from sray.platform.common.ray_address import RayAddressError, check_ray_address, split_address


def test_addresses_split_into_host_and_port() -> None:
    assert split_address("127.0.0.1:6379") == ("127.0.0.1", 6379)
    assert split_address("[::1]:6380") == ("::1", 6380)
    assert split_address("head.example.org:10001") == ("head.example.org", 10001)
    for bad in ("head", ":6379", "head:port", "head:"):
        with pytest.raises(RayAddressError, match="expected HOST:PORT"):
            split_address(bad)


def test_ray_resolved_addresses_are_left_to_ray() -> None:
    check_ray_address("auto")  # split_address would refuse both
    check_ray_address("ray://head:10001")


def test_a_closed_port_is_named_at_once() -> None:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]  # closed again when the block ends: nothing listens there
    t0 = time.monotonic()
    with pytest.raises(RayAddressError, match=f"--address 127.0.0.1:{port}: no Ray cluster answers there"):
        check_ray_address(f"127.0.0.1:{port}")
    assert time.monotonic() - t0 < 2.0


def test_a_service_that_is_not_ray_is_named_within_the_timeout() -> None:
    """A listener that accepts and never answers (another service's port): Ray's own client would wait 40 s."""
    with socket.socket() as server:
        server.bind(("127.0.0.1", 0))
        server.listen()
        port = server.getsockname()[1]
        t0 = time.monotonic()
        with pytest.raises(RayAddressError, match="something listens there but gave no Ray answer within 1 s"):
            check_ray_address(f"127.0.0.1:{port}", timeout_s=1.0)
        assert time.monotonic() - t0 < 3.0
