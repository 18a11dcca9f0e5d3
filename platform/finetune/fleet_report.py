"""The fleet's summary: a Markdown results table and per-method summary metrics for the parent run."""

from __future__ import annotations

import math
from typing import Any

from sray.platform.common.eval_protocol import EvalProtocol, caption_lines, inputs_name

COLUMNS = ("scene", "method", "inputs", "status", "attempts", "steps used", "train time (s)", "mIoU before",
           "mIoU after", "PSNR after (dB)", "artifact", "of full model", "note")
"""Table columns (``inputs``: what the row's method was given of the source views, from its protocol)."""


def _num(value: Any, digits: int) -> str:
    return "-" if value is None or (isinstance(value, float) and math.isnan(value)) else f"{value:.{digits}f}"


def human_bytes(n: int | None) -> str:
    """``n`` bytes as B / KiB / MiB / GiB with 1 decimal ("-" for None)."""
    if n is None:
        return "-"
    size, unit = float(n), "B"
    for unit in ("B", "KiB", "MiB", "GiB"):
        if size < 1024 or unit == "GiB":
            break
        size /= 1024
    return f"{int(size)} B" if unit == "B" else f"{size:.1f} {unit}"


def _inputs(r: dict[str, Any]) -> str:
    return inputs_name(EvalProtocol.from_json(r["protocol"]).inputs) if r.get("protocol") is not None else "-"


def _note(r: dict[str, Any]) -> str:
    if r["status"] != "finished":
        return str(r.get("error") or "").replace("|", "/")[:120]
    if r["stopped_early"]:
        return "early stop (held-out mIoU flat)"
    return "step budget" if r["steps_used"] >= r["max_steps"] else "time budget"


def results_table(results: list[dict[str, Any]]) -> str:
    """Markdown table of fleet results (one row per scene and method) and the protocol line(s) below it."""
    rows = [" | ".join(COLUMNS), " | ".join("---" for _ in COLUMNS)]
    for r in results:
        share = (f"{100 * r['artifact_bytes'] / r['full_checkpoint_bytes']:.2f}%"
                 if r.get("artifact_bytes") and r.get("full_checkpoint_bytes") else "-")
        rows.append(" | ".join([
            r["scene"], r["method"], _inputs(r), r["status"], str(r["attempts"]), str(r["steps_used"]),
            _num(r["wall_s"], 1), _num(r["miou_before"], 3), _num(r["miou_after"], 3), _num(r["psnr_after"], 2),
            human_bytes(r.get("artifact_bytes")), share, _note(r)]))
    lines = ["| " + row + " |" for row in rows]
    lines += ["", *caption_lines((r["method"], r.get("protocol")) for r in results),
              "Train time excludes held-out evaluation; \"of full model\" compares the scene artifact with the "
              "shared S-Ray model's tensor bytes."]
    return "\n".join(lines).strip()


def _mean(values: list[float]) -> float:
    finite = [v for v in values if v is not None and not math.isnan(v)]
    return sum(finite) / len(finite) if finite else float("nan")


def summary_metrics(results: list[dict[str, Any]]) -> dict[str, float]:
    """Per-method means over finished scenes and counts: ``<method>/miou_after_mean``, ``<method>/failed``, ..."""
    metrics: dict[str, float] = {}
    for method in sorted({r["method"] for r in results}):
        rows = [r for r in results if r["method"] == method]
        ok = [r for r in rows if r["status"] == "finished"]
        metrics[f"{method}/finished"] = float(len(ok))
        metrics[f"{method}/failed"] = float(len(rows) - len(ok))
        for key in ("miou_before", "miou_after", "psnr_after", "steps_used", "wall_s", "artifact_bytes"):
            metrics[f"{method}/{key}_mean"] = _mean([float(r[key]) for r in ok])
    return metrics
