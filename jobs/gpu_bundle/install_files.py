"""The two files that make a wheel folder a bundle a bare GPU machine can use: ``install.sh`` (the one install
command, offline) and ``README.md`` (what is inside, what was left out, how to use it)."""

from __future__ import annotations

import os
from pathlib import Path

from sray.data_tools.atomic import atomic_write_text

DEFAULT_TARGET = "/tmp/sray-site"
"""Where ``install.sh`` puts the packages unless told otherwise (then ``PYTHONPATH`` points there)."""

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
    wheels = manifest["wheels"]
    script = folder / "install.sh"
    atomic_write_text(script, INSTALL_SH.format(target=DEFAULT_TARGET, count=len(wheels)))
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
