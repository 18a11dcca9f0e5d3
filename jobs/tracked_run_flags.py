"""The flags of a command that logs what it wrote as one tracked run, and the line that tells where the run went."""

from __future__ import annotations

import argparse
from typing import Any


def add_tracked_run_flags(p: argparse.ArgumentParser, experiment: str) -> None:
    """Add ``--device``, ``--tracker``, ``--tracking-uri``, ``--experiment`` and ``--no-track`` to ``p``."""
    p.add_argument("--device", help="torch device (default: cuda if available, else cpu)")
    p.add_argument("--tracker", default="mlflow", help="tracker to log to, by registry name (default: mlflow)")
    p.add_argument("--tracking-uri", default="", help="the tracker's store, for MLflow its tracking URI (default: "
                                                      "SQLite store in this folder)")
    p.add_argument("--experiment", default=experiment, help="experiment name (default %(default)s)")
    p.add_argument("--no-track", action="store_true", help="write the files only, no tracked run")


def print_tracked_run(result: dict[str, Any]) -> None:
    """Print the tracked run's address (and how to start the UI) when ``result`` holds a ``run``."""
    if "run" in result:
        hint = result["run"]["ui_hint"]
        print(f"[sray] {result['run']['tracker']} run: {result['run']['ui_url']}"
              + (f"  (start the UI: {hint})" if hint else ""))
