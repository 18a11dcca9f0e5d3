"""Check a Ray cluster address in a second, where ``ray.init`` retries a refused token for 20 s, silence for minutes."""

from __future__ import annotations

import contextlib
import os
import socket
import threading
from collections.abc import Iterator

WHERE = "`sray cluster status` prints the address and the token variables"


class RayAddressError(ValueError):
    """``--address`` names no reachable Ray cluster, or one that refuses this client; the message says why."""


def split_address(address: str) -> tuple[str, int]:
    """``HOST:PORT`` -> (host, port); RayAddressError naming the expected form otherwise."""
    host, sep, port = address.rpartition(":")
    if not sep or not host or not port.isdigit():
        raise RayAddressError(f"--address {address!r}: expected HOST:PORT of the Ray head (its GCS port, 6379 by "
                              f"default), or 'auto'; {WHERE}")
    return host.strip("[]"), int(port)


@contextlib.contextmanager
def _quiet_stderr() -> Iterator[None]:
    """Send file descriptor 2 to /dev/null meanwhile: Ray's C++ client logs each failed attempt there."""
    saved = os.dup(2)
    try:
        with open(os.devnull, "w") as null:
            os.dup2(null.fileno(), 2)
            yield
    finally:
        os.dup2(saved, 2)
        os.close(saved)


def check_ray_address(address: str, timeout_s: float = 3.0) -> None:
    """RayAddressError unless a Ray cluster at ``address`` accepts this process's token (``auto``, ``ray://``: skip)."""
    if address == "auto" or address.startswith("ray://"):
        return
    host, port = split_address(address)
    try:
        with socket.create_connection((host, port), timeout=timeout_s):
            pass
    except OSError as e:
        raise RayAddressError(f"--address {address}: no Ray cluster answers there ({e.strerror or e}); start one "
                              f"(`sray cluster up`, `ray start --head`) or check the address; {WHERE}") from None
    refused = _ask_gcs(f"{host}:{port}", timeout_s)
    if refused is None:
        raise RayAddressError(f"--address {address}: something listens there but gave no Ray answer within "
                              f"{timeout_s:g} s; pass the head's GCS port, not another service's; {WHERE}")
    if refused:
        raise RayAddressError(f"--address {address}: the Ray cluster refused this client's token (missing or wrong); "
                              f"export RAY_AUTH_MODE=token and RAY_AUTH_TOKEN_PATH=<the cluster's token file> "
                              f"(or RAY_AUTH_TOKEN); {WHERE}")


def _ask_gcs(address: str, timeout_s: float) -> bool | None:
    """One GCS request with this process's token: False if accepted, True if refused, None without an answer."""
    from ray._raylet import GcsClient
    from ray.exceptions import AuthenticationError

    answer: list[bool] = []

    def ask() -> None:
        try:
            GcsClient(address=address)
            answer.append(False)
        except AuthenticationError:
            answer.append(True)
        except Exception:  # noqa: BLE001 - any other failure is "no Ray answer", reported by the caller
            pass

    with _quiet_stderr():
        asking = threading.Thread(target=ask, daemon=True)
        asking.start()
        asking.join(timeout_s)
    return answer[0] if answer else None
