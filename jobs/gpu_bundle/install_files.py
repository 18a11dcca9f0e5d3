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


def write_install_files(folder: Path, manifest: dict) -> None:
    """Write ``install.sh`` (executable) and ``README.md`` into the bundle ``folder``."""
    wheels = manifest["wheels"]
    script = folder / "install.sh"
    atomic_write_text(script, INSTALL_SH.format(target=DEFAULT_TARGET, count=len(wheels)))
    os.chmod(script, 0o755)
    rows = "\n".join(f"| {w['name']} | {w['version']} | {w['bytes'] / 2**20:.2f} | {' '.join(w['dropped'])} |"
                     for w in wheels)
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

| distribution | version | MiB | folders left out of the wheel |
|---|---|---:|---|
{rows}

Left out (declared dependencies sray never loads):

{left_out}
""")
