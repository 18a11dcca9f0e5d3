"""Figures of a recipe card, each read from a result sray stored: a training job's last checkpoint, an evaluation's
``metrics.json``, a fleet's ``result.json`` files and the speed-accuracy benchmark's ``tables.json``.

A reader returns the number, raises :class:`MissingField` when the file is sound but lacks the field (a result
written before sray stored it: the card says so in a note instead of a number) and :class:`ResultError`
(a ``ValueError``) when the file is absent, unreadable or holds something else than a number there. Both name
the file and the field.
"""

from __future__ import annotations

import functools
import json
import math
import pickle
from pathlib import Path
from typing import Any

from sray.jobs.bench.speed_accuracy import CHOSEN_TABLE, DEFAULT_TABLE
from sray.platform.checkpoints.folders import STATE_FILE, CheckpointManager, load_checkpoint
from sray.platform.finetune.methods.sray_method import METHOD as SRAY_METHOD
from sray.platform.finetune.scene_finetune import RESULT_FILE

FINETUNE_BUDGET_S = 60.0
"""Training seconds of the card's finetune figure."""
SPEED_COLUMN = "CPU s / view"
"""The speed-accuracy table's column a card's render time is read from."""


class ResultError(ValueError):
    """A result file that is absent, unreadable or holds the wrong kind of value; the message names file and field."""


class MissingField(Exception):
    """A sound result file without the field a card needs (written before sray stored it)."""

    def __init__(self, file: Path, field: str, why: str = "lacks") -> None:
        """``file`` ``why`` (lacks, holds null for) ``field``."""
        super().__init__(f"{file} {why} {field}")
        self.file, self.field, self.why = file, field, why


def _json(file: Path) -> Any:
    """The JSON in ``file``; ResultError when it is missing or not JSON."""
    try:
        return json.loads(Path(file).read_text())
    except FileNotFoundError:
        raise ResultError(f"{file}: no such file; fix the path in the recipe-cards list") from None
    except (OSError, ValueError) as e:
        raise ResultError(f"{file}: not readable as JSON ({e})") from None


def number(data: Any, field: str, file: Path) -> float:
    """The number at the dotted ``field`` of ``data`` (read from ``file``): MissingField when a key is absent or the
    value null, ResultError when it is something else than a finite number."""
    value = data
    for key in field.split("."):
        if not isinstance(value, dict):
            raise ResultError(f"{file}: {field}: expected an object at {key!r}, found {type(value).__name__}")
        if key not in value:
            raise MissingField(file, field)
        value = value[key]
    if value is None:
        raise MissingField(file, field, "holds null for")
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise ResultError(f"{file}: {field} is {value!r}; expected a finite number")
    return float(value)


@functools.lru_cache(maxsize=1)  # a card reads three counters of one job in a row: its state loads once
def train_state(job: Path) -> tuple[dict[str, Any], Path]:
    """The state of a training job's last checkpoint (``job``: the job folder, or one checkpoint folder) with its
    ``counters``, and that checkpoint's state file; ResultError when there is none or it does not load."""
    job = Path(job)
    checkpoint = job if (job / STATE_FILE).exists() else CheckpointManager(job / "checkpoints").latest()
    if checkpoint is None:
        raise ResultError(f"{job}: no checkpoint (neither {STATE_FILE} nor checkpoints/step_*/); give a job folder "
                          "written by `sray train`")
    try:
        return load_checkpoint(checkpoint), checkpoint / STATE_FILE
    except (RuntimeError, OSError, EOFError, pickle.UnpicklingError) as e:
        raise ResultError(f"{checkpoint / STATE_FILE}: does not load as a checkpoint ({e})") from None


def eval_miou(metrics: Path) -> float:
    """Mean over scenes of the dataset-level mIoU (0..1) in an evaluation's ``metrics.json``."""
    return number(_json(metrics), "mean.dataset_level.miou", metrics)


def finetune_miou(fleet: Path, budget_s: float = FINETUNE_BUDGET_S) -> float:
    """S-Ray's held-out mIoU (0..1) after ``budget_s`` training seconds, mean over the fleet's finished scenes: per
    scene the best point of its curve within the budget (the fleet keeps its best held-out point).

    ResultError when the fleet folder has no finished S-Ray scene, or a scene stopped before the budget that had
    neither stopped early nor used its steps (it ran with a smaller budget).
    """
    files = sorted(Path(fleet).glob(f"scenes/*/{SRAY_METHOD.name}/{RESULT_FILE}"))
    results = [(f, _json(f)) for f in files]
    finished = [(f, r) for f, r in results if isinstance(r, dict) and r.get("status") == "finished"]
    if not finished:
        raise ResultError(f"{fleet}: no scenes/*/{SRAY_METHOD.name}/{RESULT_FILE} with status 'finished'; give the "
                          "folder of a `sray finetune-fleet` run")
    scores = []
    for file, result in finished:
        curve = result.get("curve")
        if not isinstance(curve, list) or not curve:
            raise MissingField(file, "curve")
        points = [(number(p, "wall_s", file), number(p, "miou", file)) for p in curve]
        short = (points[-1][0] < budget_s and not result.get("stopped_early")
                 and number(result, "steps_used", file) < number(result, "max_steps", file))
        if short:
            raise ResultError(f"{file}: curve: training stopped at {points[-1][0]:.0f} s, before the card's "
                              f"{budget_s:g} s, with steps left: a fleet with finetune.max_seconds >= {budget_s:g}")
        scores.append(max(miou for wall, miou in points if wall <= budget_s))
    return sum(scores) / len(scores)


def _speed_table(tables: Path, setting: str) -> dict:
    """The table of the speed-accuracy benchmark's ``tables.json`` that ``setting``'s render time is read from: its
    default-settings table, or when the run measured a chosen set of settings, that table if it holds ``setting``."""
    found = {t.get("title"): t for t in _json(tables).get("tables", []) if isinstance(t, dict)}
    if DEFAULT_TABLE in found:
        return found[DEFAULT_TABLE]
    chosen = found.get(CHOSEN_TABLE)
    if chosen is not None and any(r and r[0] == setting for b in chosen.get("blocks", []) for r in b.get("rows", [])):
        return chosen
    raise MissingField(tables, f"tables[title={DEFAULT_TABLE!r}] (or a {CHOSEN_TABLE!r} table with row {setting!r})")


def speed_cpu_s(tables: Path, setting: str) -> float:
    """CPU seconds per view of ``setting`` in the speed-accuracy benchmark's ``tables.json`` (its default-settings
    table, or the chosen-settings table of a run that measured ``setting`` among others)."""
    table = _speed_table(tables, setting)
    title = table["title"]
    blocks = [b for b in table.get("blocks", []) if "header" in b]
    if not blocks or SPEED_COLUMN not in blocks[0]["header"]:
        raise MissingField(tables, f"{title!r}: column {SPEED_COLUMN!r}")
    column = blocks[0]["header"].index(SPEED_COLUMN)
    rows = [r for r in blocks[0]["rows"] if r and r[0] == setting]
    if not rows:
        raise MissingField(tables, f"{title!r}: row {setting!r}")
    try:
        return float(rows[0][column])
    except (ValueError, IndexError):
        raise ResultError(f"{tables}: {title!r}, row {setting!r}, column {SPEED_COLUMN!r}: "
                          f"{rows[0][column:column + 1]} is no number") from None


def speed_command(tables: Path, setting: str) -> str:
    """The command that measured the table ``setting``'s render time is read from (``speed_cpu_s``)."""
    table = _speed_table(tables, setting)
    if not table.get("command"):
        raise MissingField(tables, f"{table['title']!r}: command")
    return str(table["command"])
