"""Flags several commands share (here, not beside the commands, so ``jobs/bench`` may import them): those building a
registered method's pretrained model (an ``EvalRequest``; a flag its ``eval_model`` does not read (``eval_reads``)
is refused, not ignored), those of a tracked run, and the one-line refusal of bad input."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Iterable, Sequence
from typing import Any

REQUEST_FLAGS: dict[str, str] = {"--checkpoint": "checkpoint", "--segmenter": "segmenter", "--render": "fast",
                                 "--fast-stride": "fast", "--fast-confidence": "fast", "--fast-temperature": "fast",
                                 "--calibrate": "fast"}
"""Command-line flag -> the ``EvalRequest`` field it sets."""


class GivenFlag(argparse.Action):
    """``store``, and the option string added to ``namespace.given`` (a tuple): a flag given at its default counts."""

    def __call__(self, parser: argparse.ArgumentParser, namespace: argparse.Namespace, values: Any,
                 option_string: str | None = None) -> None:
        """Store ``values`` under the flag's destination and record ``option_string`` as given."""
        setattr(namespace, self.dest, values)
        namespace.given = (*getattr(namespace, "given", ()), option_string)


def flags_reading(reads: Iterable[str]) -> list[str]:
    """The flags (``REQUEST_FLAGS``) that set one of the request fields ``reads``."""
    fields = set(reads)
    return [flag for flag, field in REQUEST_FLAGS.items() if field in fields]


def unread_flags(given: Sequence[str], reads: Iterable[str]) -> list[str]:
    """The flags among ``given`` that set a request field outside ``reads``, each once, in the order given."""
    fields = set(reads)
    return [flag for flag in dict.fromkeys(given) if flag in REQUEST_FLAGS and REQUEST_FLAGS[flag] not in fields]


def refusal(flags: list[str], who: str, reads: Iterable[str]) -> str:
    """The error for ``flags`` that ``who`` (``--method 2d-transfer``) does not read: what it reads, the fix."""
    them = "it" if len(flags) == 1 else "them"
    used = ", ".join(flags_reading(reads)) or "none of these flags"
    return (f"{', '.join(flags)} {'does' if len(flags) == 1 else 'do'} not apply to {who} (it reads {used}); "
            f"drop {them}")


def add_tracker_flags(p: argparse.ArgumentParser, tracker: str | None = None, uri: str | None = None,
                      store: str = "this folder") -> None:
    """Add ``--tracker`` and ``--tracking-uri`` (None: the config's value); ``store``: the SQLite default's folder."""
    p.add_argument("--tracker", default=tracker, help="tracker to log to, by registry name (default: mlflow)")
    p.add_argument("--tracking-uri", default=uri,
                   help=f"the tracker's store, for MLflow its tracking URI (default: SQLite store in {store})")


def add_tracked_run_flags(p: argparse.ArgumentParser, experiment: str) -> None:
    """Add ``--device``, ``--tracker``, ``--tracking-uri``, ``--experiment`` and ``--no-track`` to ``p``."""
    p.add_argument("--device", help="torch device (default: cuda if available, else cpu)")
    add_tracker_flags(p, "mlflow", "")
    p.add_argument("--experiment", default=experiment, help="experiment name (default %(default)s)")
    p.add_argument("--no-track", action="store_true", help="write the files only, no tracked run")


def print_tracked_run(result: dict[str, Any]) -> None:
    """Print the tracked run's address (and how to start the UI) when ``result`` holds a ``run``."""
    if "run" in result:
        hint = result["run"]["ui_hint"]
        print(f"[sray] {result['run']['tracker']} run: {result['run']['ui_url']}"
              + (f"  (start the UI: {hint})" if hint else ""))


def refuse(command: str, message: object) -> int:
    """Print ``sray <command>: <message>`` to stderr; returns 2, the exit code of bad input."""
    print(f"sray {command}: {message}", file=sys.stderr)
    return 2
