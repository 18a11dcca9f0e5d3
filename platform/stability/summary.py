"""From the suite's point records to per-level statistics, breaking points and tables. A failed point counts as
mIoU 0 when a breaking point is found, and is drawn as a failure, never dropped.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any


@dataclass(frozen=True)
class LevelStats:
    """One (axis, method, level) over its seeds."""

    axis: str
    method: str
    level: Any
    x: float | None
    """Mean chart x over the ok seeds (None when every seed failed, or on a categorical axis)."""
    miou_mean: float | None
    miou_min: float | None
    miou_max: float | None
    psnr_mean: float | None
    n_ok: int
    n_failed: int
    psnr_min: float | None = None
    psnr_max: float | None = None


def _mean(values: list[float]) -> float | None:
    return sum(values) / len(values) if values else None


def level_stats(points: list[dict[str, Any]]) -> list[LevelStats]:
    """Group points by (axis, method, level), in first-seen order, with mean / min / max over seeds."""
    groups: dict[tuple[str, str, Any], list[dict[str, Any]]] = {}
    for p in points:
        groups.setdefault((p["axis"], p["method"], p["level"]), []).append(p)
    out = []
    for (axis, method, level), group in groups.items():
        ok = [p for p in group if p["status"] == "ok"]
        mious = [float(p["miou"]) for p in ok]
        psnrs = [float(p["psnr"]) for p in ok if p.get("psnr") is not None]
        out.append(LevelStats(axis, method, level,
                              _mean([float(p["x"]) for p in ok if isinstance(p.get("x"), (int, float))]),
                              _mean(mious), min(mious, default=None), max(mious, default=None), _mean(psnrs),
                              len(ok), len(group) - len(ok), min(psnrs, default=None), max(psnrs, default=None)))
    return out


def breaking_point(stats: list[LevelStats]) -> tuple[Any, str]:
    """(The level where one method on one axis loses half its clean mIoU, None if it never does; how it was found),
    from stats in level order (the first clean); interpolated between numeric levels, all-failed levels count 0."""
    if not stats or stats[0].miou_mean is None:
        return None, "no clean score (the clean level failed)"
    clean = stats[0].miou_mean
    half = clean / 2
    prev_level, prev_value = stats[0].level, clean
    for s in stats[1:]:
        value = 0.0 if s.miou_mean is None else s.miou_mean
        if value <= half:
            if isinstance(s.level, str) or isinstance(prev_level, str) or math.isclose(prev_value, value):
                return s.level, "first level at or below half"
            t = (prev_value - half) / (prev_value - value)
            return prev_level + t * (s.level - prev_level), "interpolated between levels"
        prev_level, prev_value = s.level, value
    return None, f"mIoU stays above {half:.1f}, half of the clean {clean:.1f}"


def _fmt(v: float | None, digits: int = 2) -> str:
    return "failed" if v is None else f"{v:.{digits}f}"


def axis_table(stats: list[LevelStats], axis: str, unit: str, headers: dict[str, str] | None = None) -> str:
    """Markdown table of one axis: a row per level, a column pair per method (mIoU with its seed range), headed by
    ``headers[method]`` (default: the method's name)."""
    rows = [s for s in stats if s.axis == axis]
    methods = list(dict.fromkeys(s.method for s in rows))
    levels = list(dict.fromkeys(s.level for s in rows))
    by = {(s.method, s.level): s for s in rows}
    names = {m: (headers or {}).get(m, m) for m in methods}
    head = f"| {unit} | " + " | ".join(f"{names[m]} mIoU % (min-max) | {names[m]} PSNR dB" for m in methods) + " |"
    lines = [head, "|" + "---|" * (1 + 2 * len(methods))]
    for level in levels:
        cells = []
        for m in methods:
            s = by.get((m, level))
            if s is None:
                cells += ["-", "-"]
                continue
            spread = "" if s.miou_mean is None else f" ({_fmt(s.miou_min, 1)}-{_fmt(s.miou_max, 1)})"
            failed = f", {s.n_failed} failed" if s.n_failed and s.n_ok else ""
            cells += [f"{_fmt(s.miou_mean)}{spread}{failed}", _fmt(s.psnr_mean)]
        lines.append(f"| {level} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def breaking_summary(stats: list[LevelStats], axes: list[str]) -> list[str]:
    """One line per (axis, method): the level at which it loses half its clean mIoU."""
    lines = []
    for axis in axes:
        rows = [s for s in stats if s.axis == axis]
        for method in dict.fromkeys(s.method for s in rows):
            level, how = breaking_point([s for s in rows if s.method == method])
            if level is None:
                lines.append(f"{axis} / {method}: keeps half its clean mIoU at every level tested ({how})")
                continue
            where = (f"{level:.3g}" if isinstance(level, float) else str(level)) + f" ({how})"
            lines.append(f"{axis} / {method}: half the clean mIoU lost at {where}")
    return lines
