"""The default-render rule applied to ``sray bench speed-accuracy``'s rows, and its verdict table."""

from __future__ import annotations

from pathlib import Path

from sray.jobs.bench.render_default import DefaultChoice, choose_default, todays_defaults
from sray.jobs.bench.speed_accuracy import Setting
from sray.jobs.bench.speed_classes import measured
from sray.platform.common.doc_blocks import markdown_table


def rule_choice(rows: list[dict], settings: list[Setting]) -> DefaultChoice | None:
    """The rule over S-Ray's rows whose settings evaluate as the first row's (``Setting.same_evaluation``), against
    it; None when the first row is not a full render (no reference for the losses)."""
    by_name = {s.name: s for s in settings}
    first = by_name[rows[0]["name"]]
    if first.fast is not None:
        return None
    offered = [r for r in rows if r["setting"] is not None and by_name[r["name"]].same_evaluation(first)]
    return choose_default([measured(r) for r in offered], first.name)


def todays_settings(settings: list[Setting]) -> dict[str, str | None]:
    """Each user of a default render -> the setting that renders as it does on the optimised path (None: none)."""
    found = {}
    for user, fast in todays_defaults().items():
        match = [s.name for s in settings if s.same_evaluation(settings[0]) and s.impl == "fast" and s.fast == fast]
        found[user] = match[0] if match else None
    return found


def checkpoint_label(path: Path) -> str:
    """``<job>/<step folder>`` for a job's checkpoint, else its folder name."""
    path = Path(path)
    return f"{path.parent.parent.name}/{path.name}" if path.parent.name == "checkpoints" else path.name


def today_cell(choice: DefaultChoice, today: dict[str, str | None]) -> str:
    """Whether each of today's defaults passes: ``sray eval (fast s8 c0.9): fails (chair -4.20)``."""
    users: dict[str | None, list[str]] = {}
    for user, name in today.items():
        users.setdefault(name, []).append(user)
    parts = []
    for name, who in users.items():
        if name is None or name not in choice.shortfalls:
            parts.append(f"{', '.join(who)}: not measured")
            continue
        why = ", ".join(s.describe() for s in choice.shortfalls[name])
        parts.append(f"{', '.join(who)} ({name}): " + (f"fails ({why})" if why else "passes"))
    return "; ".join(parts)


def verdict_table(labels: list[str], choices: list[DefaultChoice], today: dict[str, str | None]) -> str:
    """Per checkpoint (or mean): the setting chosen, each faster one rejected and why, whether today's defaults pass."""
    lines = []
    for label, choice in zip(labels, choices, strict=True):
        rejected = "; ".join(f"{name}: {', '.join(s.describe() for s in why)}"
                             for name, why in choice.rejected().items())
        lines.append([label, choice.chosen, rejected or "none", today_cell(choice, today)])
    return markdown_table(["checkpoint", "default by the rule", "faster settings rejected (points lost)",
                           "today's defaults"], lines)
