"""What a stopped trial already scored: a rerun of the study reuses the calibration and each split's ``metrics.json``
written for the same checkpoint, rooms and protocol, and evaluates only the rest (a trial's evaluations take longer
than its training on a 2-core machine)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from sray.model.fast_render import FastRender
from sray.platform.common.eval_protocol import EvalProtocol


def _stored(path: Path) -> dict[str, Any] | None:
    """The JSON object at ``path``; None when it is absent or unreadable (written atomically, so never half)."""
    try:
        data = json.loads(Path(path).read_text())
    except (OSError, ValueError):
        return None
    return data if isinstance(data, dict) else None


def _same_path(a: object, b: Path) -> bool:
    """Whether the stored path ``a`` names the file or folder ``b`` (links resolved)."""
    return isinstance(a, str) and Path(a).resolve() == Path(b).resolve()


def stored_calibration(path: Path, checkpoint: Path, validation: Path, n_source: int,
                       stride: int) -> dict[str, Any] | None:
    """The temperature fit stored at ``path`` when it fitted ``checkpoint`` on the ``validation`` shards with these
    sources and pixel stride; None otherwise."""
    fitted = _stored(path)
    same = (fitted is not None and _same_path(fitted.get("checkpoint"), checkpoint)
            and _same_path(fitted.get("shards"), validation)
            and (fitted.get("n_source"), fitted.get("stride")) == (n_source, stride))
    return fitted if same else None


def stored_report(metrics: Path, checkpoint: Path, shards: Path, scenes: list[str], n_source: int,
                  fast: FastRender | None) -> dict[str, Any] | None:
    """The ``sray eval`` report stored at ``metrics`` when it scored ``checkpoint`` on exactly ``scenes`` of
    ``shards`` with ``n_source`` sources and the render ``fast`` (None: full); None otherwise."""
    report = _stored(metrics)
    if report is None:
        return None
    protocol = report.get("protocol") or {}
    render = EvalProtocol(source_rule="", n_source=n_source, stride=1).rendered_by(fast).render  # as eval records it
    same = (_same_path(report.get("checkpoint"), checkpoint) and _same_path(report.get("shards"), shards)
            and sorted(report.get("scenes") or {}) == sorted(scenes) and protocol.get("n_source") == n_source
            and protocol.get("render") == render)
    return report if same else None
