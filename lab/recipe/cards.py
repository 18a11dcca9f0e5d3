"""``sray lab recipe-cards``: one table of every recipe of ``RECIPES`` on every machine, read from stored results,
stored as data like every benchmark table and written into its page (section "Recipe cards (all machines)"), and with
``--readme`` between :data:`README_START` and :data:`README_END` of that file. The repository's README publishes its
cards from the stored table with ``python -m sray.lab.publish``.

The results are named in a JSON list (paths relative to the list's folder)::

    {"machines": ["2-core CPU"],
     "runs": [{"recipe": "synth-cpu-hour", "machine": "2-core CPU", "train": "train/bench-long-s0",
               "zero_shot": "eval/long-s0/metrics.json", "held_out": "eval-heldout/long-s0/metrics.json",
               "finetune": "fleet-60s", "speed": "docs/benchmarks/speed-accuracy/cpu-only/tables.json"}]}

``machines`` (optional) adds machines nothing ran on yet; every recipe gets a row on every machine, and a recipe
with no run there says ``not run on <machine>``. A run's results are each optional (:class:`RunEntry`); one not
given shows ``not measured``, a field its file lacks shows ``missing (n)`` with note n naming the file and field.
"""

from __future__ import annotations

import dataclasses
import json
import os
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from sray.data_tools.atomic import atomic_write_text
from sray.platform.common.bench_doc import DEFAULT_DOC, Bench, record
from sray.platform.common.doc_blocks import markdown_table, portable
from sray.lab.recipe.results import (
    FINETUNE_BUDGET_S,
    MissingField,
    eval_miou,
    finetune_miou,
    number,
    speed_command,
    speed_cpu_s,
    train_state,
)
from sray.jobs.bench.speed_accuracy import default_settings
from sray.jobs.bench.speed_verdict import todays_settings
from sray.platform.config.recipes import RECIPES
from sray.platform.finetune.fleet_report import human_bytes

CARDS = Bench("recipe-cards", "Recipe cards")
"""The cards' section of docs/benchmarks.md."""
KIND = "all machines"
"""The section's device: each row names its own machine."""
README_START, README_END = "<!-- recipe-cards:start -->", "<!-- recipe-cards:end -->"
"""The README lines between which the cards are written."""


@dataclass(frozen=True)
class RunEntry:
    """One recipe's results on one machine, as the list names them."""

    recipe: str
    """A name of ``RECIPES``."""
    machine: str
    """The machine it ran on, as the table shows it."""
    train: Path | None = None
    """The pretraining job's folder (or one of its checkpoints): wall time, CPU time, peak memory."""
    zero_shot: Path | None = None
    """``metrics.json`` of ``sray eval`` on unseen scenes."""
    held_out: Path | None = None
    """``metrics.json`` of ``sray eval --scenes`` on held-out views of training scenes."""
    finetune: Path | None = None
    """A ``sray finetune-fleet`` folder with S-Ray results of at least 60 training seconds."""
    speed: Path | None = None
    """``tables.json`` of ``sray bench speed-accuracy`` on this recipe's checkpoint."""


def read_listing(path: Path) -> tuple[list[str], list[RunEntry]]:
    """The machines (listed ones, then those the runs name) and the runs of a recipe-cards list; ValueError naming
    the file and the entry for an unknown key or recipe, a missing recipe or machine, or a repeated pair."""
    path = Path(path)
    data = _listing_json(path)
    keys = [f.name for f in dataclasses.fields(RunEntry)]
    runs = []
    for i, run in enumerate(data.get("runs", [])):
        where = f"{path}: runs[{i}]"
        if not isinstance(run, dict) or not isinstance(run.get("recipe"), str) or not run.get("machine"):
            raise ValueError(f"{where}: give an object with at least \"recipe\" and \"machine\"")
        unknown = sorted(set(run) - set(keys))
        if unknown:
            raise ValueError(f"{where}: unknown keys {unknown}; known: {keys}")
        if run["recipe"] not in RECIPES:
            raise ValueError(f"{where}: recipe {run['recipe']!r} is not one of {list(RECIPES)}")
        paths = {k: v for k, v in run.items() if k not in ("recipe", "machine")}
        wrong = [k for k, v in paths.items() if not isinstance(v, str) or not v]
        if wrong:
            raise ValueError(f"{where}: {wrong[0]} must be a path (a string, relative to the list's folder)")
        paths = {k: path.parent / v for k, v in paths.items()}
        runs.append(RunEntry(recipe=run["recipe"], machine=str(run["machine"]), **paths))
    pairs = [(r.recipe, r.machine) for r in runs]
    repeated = sorted({p for p in pairs if pairs.count(p) > 1})
    if repeated:
        raise ValueError(f"{path}: recipe and machine {repeated[0]} named twice; keep one run per pair")
    machines = [str(m) for m in data.get("machines", [])]
    return machines + [m for m in dict.fromkeys(r.machine for r in runs) if m not in machines], runs


def _listing_json(path: Path) -> dict:
    """The list's JSON object; ValueError naming the file when it is absent, not JSON or not an object."""
    try:
        data = json.loads(path.read_text())
    except (OSError, ValueError) as e:
        raise ValueError(f"{path}: the recipe-cards list is not readable JSON ({e})") from None
    if not isinstance(data, dict) or not isinstance(data.get("runs", []), list):
        raise ValueError(f"{path}: expected an object {{\"runs\": [...]}} (module docstring of recipe_cards.py)")
    return data


@dataclass(frozen=True)
class Column:
    """One figure of a card: its header, how it is read from a run's results (``read(run)``: the number, None when
    the run names no such result) and how it is shown."""

    header: str
    read: Callable[[RunEntry], float | None]
    show: Callable[[float], str]


def _duration(seconds: float) -> str:
    """``45 s``, ``12.5 min`` or ``1.52 h``."""
    return f"{seconds:.0f} s" if seconds < 90 else f"{seconds / 60:.1f} min" if seconds < 7200 else \
        f"{seconds / 3600:.2f} h"


def _counter(name: str) -> Callable[[RunEntry], float | None]:
    """Reads ``counters.<name>`` of the run's training job's last checkpoint."""
    def read(run: RunEntry) -> float | None:
        if run.train is None:
            return None
        state, file = train_state(run.train)
        return number(state, f"counters.{name}", file)
    return read


def columns(render_setting: str) -> list[Column]:
    """The card's figures; the render time is the speed-accuracy row of ``render_setting``."""
    def optional(path: Callable[[RunEntry], Path | None], reader: Callable[[Path], float]) -> Callable:
        """``reader`` of the run's result at ``path(run)``; None when the run names none."""
        return lambda run: None if path(run) is None else reader(path(run))

    return [
        Column("pretraining wall", _counter("wall_seconds"), _duration),
        Column("pretraining CPU", _counter("cpu_seconds"), _duration),
        Column("peak memory (rank 0)", _counter("peak_memory_mb"), lambda mb: human_bytes(round(mb * 2**20))),
        Column("zero-shot mIoU", optional(lambda r: r.zero_shot, eval_miou), lambda v: f"{100 * v:.1f}%"),
        Column("held-out train-scene mIoU", optional(lambda r: r.held_out, eval_miou), lambda v: f"{100 * v:.1f}%"),
        Column(f"{FINETUNE_BUDGET_S:g} s finetune mIoU", optional(lambda r: r.finetune, finetune_miou),
               lambda v: f"{100 * v:.1f}%"),
        Column(f"render CPU s / view ({render_setting})",
               optional(lambda r: r.speed, lambda p: speed_cpu_s(p, render_setting)), lambda v: f"{v:.2f}"),
    ]


def cards_table(machines: list[str], runs: list[RunEntry], render_setting: str) -> tuple[str, list[str]]:
    """The cards as a Markdown table (a row per machine and recipe) and its notes: one per missing field, numbered
    as the ``missing (n)`` cells that point to them. ResultError from a bad result file."""
    cols, notes, rows = columns(render_setting), [], []
    by_pair = {(r.recipe, r.machine): r for r in runs}
    for machine in machines:
        for recipe in RECIPES:
            run = by_pair.get((recipe, machine))
            if run is None:
                rows.append([recipe, machine, f"not run on {machine}", *["—" for _ in cols[1:]]])
                continue
            cells = []
            for col in cols:
                try:
                    value = col.read(run)
                    cells.append("not measured" if value is None else col.show(value))
                except MissingField as missing:
                    notes.append(f"({len(notes) + 1}) {missing}")
                    cells.append(f"missing ({len(notes)})")
            rows.append([recipe, machine, *cells])
    return markdown_table(["recipe", "machine", *(c.header for c in cols)], rows), notes


def replace_between(path: Path, block: str, start: str = README_START, end: str = README_END) -> None:
    """Write ``block`` between the lines ``start`` and ``end`` of ``path`` (atomically), leaving every other byte
    as it was; ValueError naming the file and the markers when they are not there once each, in order."""
    text = Path(path).read_text()
    if text.count(start) != 1 or text.count(end) != 1 or text.index(start) > text.index(end):
        raise ValueError(f"{path}: needs the lines {start} and {end} once each, in that order, where the recipe cards "
                         "go")
    head, rest = text.split(start, 1)
    tail = rest.split(end, 1)[1]
    atomic_write_text(Path(path), f"{head}{start}\n{block.strip()}\n{end}{tail}")


def run_recipe_cards(listing: Path, readme: Path | None, doc: Path = DEFAULT_DOC) -> str:
    """Read the results ``listing`` names, write the cards into ``readme`` (between the markers; None: no README) and
    into ``doc``'s section; returns the table. ValueError (ResultError included) names the file and field at fault."""
    machines, runs = read_listing(listing)
    render_setting = todays_settings(default_settings())["sray eval"]
    if render_setting is None:
        raise ValueError("sray eval's default render is none of the speed-accuracy settings; add it to "
                         "jobs/bench/speed_accuracy.py default_settings()")
    table, missing = cards_table(machines, runs, render_setting)
    notes = "\n\n".join([*missing, sources(render_setting, _speed_commands(runs, render_setting))])
    # the listing's own path joins the paths OUT is made of: a single result outside the repository keeps its path
    # below the listing's folder instead of shrinking to OUT/<file name>
    if readme is not None:
        [readme_text, _] = portable([f"{table}\n\n{notes}", os.path.abspath(listing)],
                                    Path(os.path.abspath(readme)).parent)
        replace_between(readme, readme_text)  # first: a README without the markers leaves both files as they were
    record(CARDS, CARDS.title, table, doc, notes, kind=KIND)
    return table


def _speed_commands(runs: list[RunEntry], render_setting: str) -> list[str]:
    """The commands that measured the runs' speed tables read for ``render_setting`` (a table without one is a note
    of the cards already)."""
    found = set()
    for run in (r for r in runs if r.speed is not None):
        try:
            found.add(f"`{speed_command(run.speed, render_setting)}`")
        except MissingField:
            continue
    return sorted(found)


def sources(render_setting: str, speed_commands: list[str]) -> str:
    """Where each figure comes from."""
    return (f"Read by `sray lab recipe-cards` from stored results: pretraining wall time, CPU time (all ranks and "
            f"their loader processes) and rank 0's peak memory (resident set on a CPU, CUDA allocator peak on a GPU) "
            f"from the job's last checkpoint (`counters`); zero-shot and held-out train-scene mIoU (dataset-level, "
            f"mean over scenes) from `sray eval`'s metrics.json; the finetune mIoU from the fleet's S-Ray "
            f"result.json files (per scene the best held-out point within {FINETUNE_BUDGET_S:g} training seconds, "
            f"mean over scenes); render CPU seconds per view of '{render_setting}' (`sray eval`'s default render) "
            f"from the speed-accuracy table" + (f" measured by {', '.join(speed_commands)}." if speed_commands
                                                 else "."))
