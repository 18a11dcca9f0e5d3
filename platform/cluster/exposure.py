"""Which of a local cluster's processes listen beyond loopback (the kernel's socket table): Ray 2.60's GCS and
raylets listen on every interface whatever ``--node-ip-address`` says, guarded by the token (docs/cluster.md)."""

from __future__ import annotations

import ipaddress
from dataclasses import dataclass

import psutil


@dataclass(frozen=True)
class Listener:
    """A listening TCP socket: the part whose process tree holds it (``ray-head`` ...), the owner's name (``raylet``
    ...) and pid, the bound address (``0.0.0.0`` / ``::``: every interface) and the port."""

    part: str
    process: str
    pid: int
    address: str
    port: int

    @property
    def loopback_only(self) -> bool:
        """Whether only this machine can connect (a loopback address, IPv4-mapped ones included; not a wildcard)."""
        address = ipaddress.ip_address(self.address.split("%")[0])
        mapped = getattr(address, "ipv4_mapped", None)
        return (mapped or address).is_loopback


def listeners(parts: dict[str, int]) -> list[Listener]:
    """Listening TCP sockets of each part's process tree (``parts``: name -> root pid; gone: none), by part, port."""
    owner: dict[int, tuple[str, str]] = {}
    for part, pid in parts.items():
        try:
            root = psutil.Process(pid)
            for proc in [root, *root.children(recursive=True)]:
                owner[proc.pid] = (part, proc.name())
        except psutil.NoSuchProcess:
            continue
    found = {Listener(owner[c.pid][0], owner[c.pid][1], c.pid, c.laddr.ip, c.laddr.port)
             for c in psutil.net_connections(kind="tcp") if c.status == psutil.CONN_LISTEN and c.pid in owner}
    return sorted(found, key=lambda x: (x.part, x.port, x.address))


def exposure_line(found: list[Listener]) -> str:
    """Status lines: every port on loopback, or which ones other hosts can reach."""
    open_ = [x for x in found if not x.loopback_only]
    if not open_:
        return f"[cluster] network: all {len(found)} listening ports are on loopback only"
    listed = ", ".join(f"{x.part}/{x.process} {x.address}:{x.port}" for x in open_)
    return (f"[cluster] network: {len(open_)} of {len(found)} listening ports accept connections beyond loopback "
            f"(Ray's own; guarded by the Ray token, firewall them on a shared host):\n[cluster]   {listed}")
