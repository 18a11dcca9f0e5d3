"""Build the GPU bundle: resolve (:mod:`.resolve`), download, repack Ray without what sray never loads, refuse one
over a GPU call's size limit, write ``install.sh`` (offline) and ``README.md``; built beside ``out``, renamed whole."""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

from sray.data_tools.atomic import atomic_write_json, atomic_write_text, replace_dir

from .image import normalise
from .resolve import LEFT_OUT, BundleError, Pin, bundle_pins, check_pins, read_constraints, resolve, target_options
from .wheel_strip import strip_wheel

DROP = {"ray": ("ray/jars/", "ray/dashboard/client/build/", "ray/rllib/", "ray/serve/", "ray/llm/")}
"""Folders left out of a wheel: Ray's Java workers (``ray_dist.jar``), its dashboard's web page (sray starts Ray
without the dashboard) and its RLlib, Serve and LLM libraries (sray imports none)."""
STRIP = {"ray": ("ray/_raylet.so", "ray/core/src/ray/gcs/gcs_server", "ray/core/src/ray/raylet/raylet")}
"""Native binaries stripped of their symbol tables: Ray's three largest."""
LIMIT_MIB = 60.0
"""Most a bundle may weigh: a GPU call carries 64 MiB, the checkout included."""
MANIFEST = "bundle.json"
DEFAULT_TARGET = "/tmp/sray-site"
"""Where ``install.sh`` puts the packages unless told otherwise."""
INSTALL_SH = """#!/bin/sh
# Install this bundle's wheels offline into a folder (default {target}); then put it on PYTHONPATH.
# Usage: sh install.sh [TARGET]   (PYTHON=... picks the interpreter; default python3)
set -eu
here=$(cd "$(dirname "$0")" && pwd)
target=${{1:-{target}}}
"${{PYTHON:-python3}}" -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade \\
    --target "$target" "$here"/*.whl
echo "gpu-bundle: {count} wheels installed into $target; now: export PYTHONPATH=$target${{PYTHONPATH:+:$PYTHONPATH}}"
"""


def download(pins: list[Pin], dest: Path, python_version: str, find_links: Path | None = None) -> None:
    """Download one wheel per pin (no dependencies) for CPython ``python_version`` on manylinux x86-64 into ``dest``,
    from ``find_links`` alone when given; :class:`BundleError` naming the package without a wheel, and the fix."""
    where = ["--no-index", "--find-links", str(find_links)] if find_links else []
    done = subprocess.run([sys.executable, "-m", "pip", "download", "-q", "--no-deps", *where, "-d", str(dest),
                           *target_options(python_version), *(p.spec() for p in pins)],
                          capture_output=True, text=True, check=False)
    if done.returncode != 0:
        found = re.search(r"(?:No matching distribution found for|version that satisfies the requirement) (\S+)",
                          done.stderr)
        name = found.group(1) if found else "one of the pins"
        source = f"in {find_links}" if find_links else "on the registry"
        raise BundleError(f"no wheel of {name} for CPython {python_version} on manylinux x86-64 {source}: pin a "
                          "version that has one in constraints.txt, or add its platform tag (manylinux_2_N_x86_64) to "
                          "MANYLINUX_TAGS in jobs/gpu_bundle/resolve.py, and build again")


def match_wheels(pins: list[Pin], folder: Path) -> dict[str, Path]:
    """``name -> wheel`` for every pin from ``folder``; :class:`BundleError` for a pin without exactly one wheel."""
    wheels: dict[str, list[Path]] = {}
    for path in sorted(folder.glob("*.whl")):
        wheels.setdefault(normalise(path.name.split("-", 1)[0]), []).append(path)
    missing = [p.spec() for p in pins if len(wheels.get(p.name, [])) == 0]
    doubled = [p.spec() for p in pins if len(wheels.get(p.name, [])) > 1]
    if missing or doubled:
        problems = [f"{what} {', '.join(specs)}" for what, specs in (("no wheel for", missing),
                                                                    ("several wheels for", doubled)) if specs]
        raise BundleError(f"{'; '.join(problems)} in {folder}: run `sray gpu-bundle` again (it downloads exactly one "
                          "of each)")
    return {p.name: wheels[p.name][0] for p in pins}


def folder_bytes(folder: Path) -> int:
    """Total size of the files in ``folder`` (not recursive)."""
    return sum(p.stat().st_size for p in folder.iterdir() if p.is_file())


def assemble(pins: list[Pin], wheels: Path, out: Path, python_version: str, limit_mib: float = LIMIT_MIB) -> dict:
    """Write the bundle folder ``out`` (repacked ``wheels``, ``install.sh``, ``README.md``, ``bundle.json``); returns
    the manifest. :class:`BundleError`, ``out`` untouched, for a missing wheel or a bundle over ``limit_mib``."""
    found = match_wheels(pins, wheels)
    work = out.with_name(f".{out.name}.tmp{os.getpid()}")
    shutil.rmtree(work, ignore_errors=True)
    work.mkdir(parents=True)
    try:
        entries = []
        for pin in pins:
            drop, binaries = DROP.get(pin.name, ()), STRIP.get(pin.name, ())
            if drop or binaries:
                try:
                    path = strip_wheel(found[pin.name], work, drop, binaries).path
                except ValueError as err:
                    raise BundleError(str(err)) from None
            else:
                path = work / found[pin.name].name
                shutil.copyfile(found[pin.name], path)
            entries.append({"name": pin.name, "version": pin.version, "file": path.name,
                            "bytes": path.stat().st_size, "dropped": list(drop), "symbols_stripped": list(binaries)})
        manifest = {"python_version": python_version, "platform": "manylinux x86-64", "wheels": entries,
                    "left_out": LEFT_OUT}
        write_install_files(work, manifest)
        atomic_write_json(work / MANIFEST, manifest)
        total = folder_bytes(work)
        if total > limit_mib * 2**20:
            largest = ", ".join("{file} {mib:.1f} MiB".format(file=e["file"], mib=e["bytes"] / 2**20)
                                for e in sorted(entries, key=lambda e: -e["bytes"])[:3])
            raise BundleError(f"the bundle would weigh {total / 2**20:.1f} MiB, over its {limit_mib:g} MiB limit "
                              f"(largest: {largest}): leave out more of what sray never loads (DROP in "
                              "jobs/gpu_bundle/build.py, LEFT_OUT in jobs/gpu_bundle/resolve.py)")
        replace_dir(work, out, out.with_name(f".{out.name}.old{os.getpid()}"))
    finally:
        shutil.rmtree(work, ignore_errors=True)
    return manifest


def build_bundle(out: Path, python_version: str, constraints_file: Path, limit_mib: float = LIMIT_MIB,
                 find_links: Path | None = None) -> dict:
    """Resolve, check the pins, download and assemble the bundle; its manifest (else :class:`BundleError`)."""
    pins = bundle_pins(resolve(python_version, constraints_file))
    check_pins(pins, read_constraints(constraints_file))
    downloads = out.with_name(f".{out.name}.downloads{os.getpid()}")
    shutil.rmtree(downloads, ignore_errors=True)
    try:
        download(pins, downloads, python_version, find_links)
        return assemble(pins, downloads, out, python_version, limit_mib)
    finally:
        shutil.rmtree(downloads, ignore_errors=True)


def bundle_table(manifest: dict) -> str:
    """The bundle's wheels as a Markdown table: name, version, MiB and what the repack changed, then the total."""
    rows = []
    for w in manifest["wheels"]:
        changes = ([f"without {' '.join(w['dropped'])}"] if w["dropped"] else []) + (
            [f"symbols stripped from {' '.join(w['symbols_stripped'])}"] if w["symbols_stripped"] else [])
        rows.append(f"| {w['name']} | {w['version']} | {w['bytes'] / 2**20:.2f} | {'; '.join(changes)} |")
    total = sum(w["bytes"] for w in manifest["wheels"]) / 2**20
    return ("| distribution | version | MiB | repacked |\n|---|---|---:|---|\n" + "\n".join(rows)
            + f"\n| **{len(rows)} wheels** | | **{total:.1f}** | |")


def write_install_files(folder: Path, manifest: dict) -> None:
    """Write ``install.sh`` (executable) and ``README.md`` into the bundle ``folder``."""
    script = folder / "install.sh"
    atomic_write_text(script, INSTALL_SH.format(target=DEFAULT_TARGET, count=len(manifest["wheels"])))
    os.chmod(script, 0o755)
    left_out = "\n".join(f"- {name}: {why}" for name, why in manifest["left_out"].items())
    atomic_write_text(folder / "README.md", f"""# sray GPU bundle (CPython {manifest['python_version']}, \
{manifest['platform']})

What sray needs at `sray gpu-check`'s `ray` and `fleet` stages beyond the GPU image (which has torch, accelerate,
numpy, pandas, pyarrow, OpenCV, matplotlib and the rest listed in `jobs/gpu_bundle/image.py`). Install it offline,
with no dependency resolution (the set is resolved already):

```
sh install.sh {DEFAULT_TARGET} && export PYTHONPATH={DEFAULT_TARGET}
```

(that is `python3 -m pip install --no-index --no-deps --no-compile --target {DEFAULT_TARGET} *.whl`). Built by
`sray gpu-bundle` (`make gpu-bundle`); `bundle.json` lists the same in data.

{bundle_table(manifest)}

Left out (declared dependencies sray never loads):

{left_out}
""")
