"""Repack a wheel without some files and with named native binaries stripped of symbols (only crash backtraces lose
names): ``RECORD`` rewritten, dropped modules' console scripts removed, file modes kept; pip installs it as before."""

from __future__ import annotations

import base64
import hashlib
import io
import shutil
import subprocess
import tempfile
import zipfile
from dataclasses import dataclass
from pathlib import Path

from sray.data_tools.atomic import atomic_write_bytes


@dataclass(frozen=True)
class Stripped:
    """What one repack did: the new wheel, files left out and bytes saved (uncompressed)."""

    path: Path
    dropped_files: int
    dropped_bytes: int


def record_hash(data: bytes) -> str:
    """The ``RECORD`` hash field of ``data``: ``sha256=`` and the URL-safe base64 digest without padding."""
    return "sha256=" + base64.urlsafe_b64encode(hashlib.sha256(data).digest()).rstrip(b"=").decode()


def dist_info_dir(names: list[str], wheel: Path) -> str:
    """The wheel's one ``*.dist-info`` folder (with a trailing ``/``); raises ``ValueError`` without one."""
    folders = {n.split("/", 1)[0] + "/" for n in names if n.split("/", 1)[0].endswith(".dist-info")}
    if len(folders) != 1:
        raise ValueError(f"{wheel}: expected one .dist-info folder, found {sorted(folders) or 'none'}")
    return folders.pop()


def filter_entry_points(text: str, drop: tuple[str, ...]) -> str:
    """``entry_points.txt`` without the entries whose ``module:attr`` lives under a dropped folder."""
    def dropped(line: str) -> bool:
        module_path = line.split("=", 1)[1].split(":", 1)[0].strip().replace(".", "/")
        return any((module_path + "/").startswith(prefix) for prefix in drop)

    kept = [line for line in text.splitlines() if "=" not in line or line.lstrip().startswith("[") or not dropped(line)]
    return "\n".join(kept) + "\n"


def strip_symbols(data: bytes) -> bytes:
    """``data`` (an ELF binary) after ``strip --strip-unneeded``; ValueError where ``strip`` is missing or fails."""
    if shutil.which("strip") is None:
        raise ValueError("binutils' strip is not installed: apt-get install binutils, then build again")
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "binary"
        path.write_bytes(data)
        done = subprocess.run(["strip", "--strip-unneeded", str(path)], capture_output=True, text=True, check=False)
        if done.returncode != 0:
            raise ValueError(f"strip refused a binary: {done.stderr.strip()}")
        return path.read_bytes()


def strip_wheel(src: Path, dest_dir: Path, drop: tuple[str, ...], binaries: tuple[str, ...] = ()) -> Stripped:
    """Write ``src`` into ``dest_dir`` without the files under the ``drop`` folders (each ending in ``/``) and with
    the ``binaries`` stripped; ValueError for a folder or binary not in the wheel (a stale list) or in .dist-info."""
    bad = [p for p in drop if not p.endswith("/") or ".dist-info/" in p]
    if bad:
        raise ValueError(f"folders to drop must end in '/' and stay out of .dist-info: {bad}")
    dest = dest_dir / src.name
    dropped_files = dropped_bytes = 0
    with zipfile.ZipFile(src) as zin:
        infos = zin.infolist()
        info_dir = dist_info_dir([i.filename for i in infos], src)
        missing = [p for p in drop if not any(i.filename.startswith(p) for i in infos)]
        missing += [b for b in binaries if b not in {i.filename for i in infos}]
        if missing:
            raise ValueError(f"{src.name} has no {', '.join(missing)}: update the lists of what to drop")
        record_name, records, buffer = info_dir + "RECORD", [], io.BytesIO()
        with zipfile.ZipFile(buffer, "w", zipfile.ZIP_DEFLATED) as zout:
            for info in infos:
                if info.filename == record_name or info.is_dir():
                    continue
                if any(info.filename.startswith(p) for p in drop):
                    dropped_files, dropped_bytes = dropped_files + 1, dropped_bytes + info.file_size
                    continue
                data = zin.read(info)
                if info.filename == info_dir + "entry_points.txt":
                    data = filter_entry_points(data.decode(), drop).encode()
                elif info.filename in binaries:
                    dropped_bytes += len(data)
                    data = strip_symbols(data)
                    dropped_bytes -= len(data)
                zout.writestr(_copy_info(info), data)
                records.append(f"{info.filename},{record_hash(data)},{len(data)}")
            records.append(f"{record_name},,")
            zout.writestr(_copy_info(zin.getinfo(record_name)), "\n".join(records) + "\n")
    atomic_write_bytes(dest, buffer.getvalue())
    return Stripped(dest, dropped_files, dropped_bytes)


def _copy_info(info: zipfile.ZipInfo) -> zipfile.ZipInfo:
    """A new entry with the original's name, time and permission bits, deflated."""
    copy = zipfile.ZipInfo(info.filename, date_time=info.date_time)
    copy.external_attr, copy.compress_type = info.external_attr, zipfile.ZIP_DEFLATED
    return copy
