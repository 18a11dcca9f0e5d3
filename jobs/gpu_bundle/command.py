"""``sray gpu-bundle``: the wheels a bare GPU machine needs beyond its image, as one folder with its install script;
``--check`` proves one installs offline and runs the prepared GPU call there in a dry run (docs/gpu.md)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from .build import LIMIT_MIB

GPU_PYTHON = "3.12"  # the GPU image's


def register(sub: argparse._SubParsersAction) -> None:
    """Add ``sray gpu-bundle``."""
    p = sub.add_parser("gpu-bundle", help="the wheels a bare GPU machine needs beyond its image, in one folder")
    p.add_argument("--python-version", default=None,
                   help=f"target CPython (default {GPU_PYTHON}, the GPU image's; with --check, this machine's)")
    p.add_argument("--out", type=Path, default=None,
                   help="bundle folder (default outputs/gpu-bundle; with --check, outputs/gpu-bundle-check)")
    p.add_argument("--constraints", type=Path, default=Path("constraints.txt"), help="the pins (constraints.txt)")
    p.add_argument("--find-links", type=Path, default=None, help="take the wheels from this folder, offline")
    p.add_argument("--limit-mib", type=float, default=LIMIT_MIB, help="refuse a bundle heavier than this")
    p.add_argument("--check", action="store_true",
                   help="build for this machine's Python, make a clean venv with the CPU torch, and run the prepared "
                        "GPU call there in a dry run: the bundle installed offline, then the ray, fleet and minutes "
                        "stages (slow: minutes)")
    p.set_defaults(func=_gpu_bundle)


def _gpu_bundle(args: argparse.Namespace) -> int:
    from .build import build_bundle, folder_bytes
    from .check import run_bundle_check
    from .resolve import BundleError

    here = f"{sys.version_info.major}.{sys.version_info.minor}"
    try:
        if args.check:
            return run_bundle_check(args.out or Path("outputs/gpu-bundle-check"), args.python_version or here,
                                    args.constraints, args.limit_mib)
        out = args.out or Path("outputs/gpu-bundle")
        manifest = build_bundle(out, args.python_version or GPU_PYTHON, args.constraints, args.limit_mib,
                                args.find_links)
    except BundleError as err:
        print(f"sray gpu-bundle: {err}")
        return 2
    print(f"sray gpu-bundle: {len(manifest['wheels'])} wheels, {folder_bytes(out) / 2**20:.1f} MiB, for "
          f"CPython {manifest['python_version']} in {out}; install there with: sh {out}/install.sh")
    return 0
