"""The published figures: each generated block of the README and the docs is one renderer here, a function of the
repository's stored results (``jobs/studies/results/``, ``docs/benchmarks/*/*/*.json``) returning the block's
Markdown. :data:`RENDERERS` names them; each block's text names the files it was read from."""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path

from sray.lab.publish.bench_data import markdown_table
from sray.lab.publish.results import RESULTS, figure, mean_sd, present, seeds, spread, trials
from sray.lab.publish.step_cost import appearance_step_cost

CARDS_DATA = Path("docs/benchmarks/recipe-cards/all-machines/tables.json")
"""The recipe cards' stored table (``sray lab recipe-cards``)."""
H100_REPORT = Path("docs/benchmarks/gpu-check/nvidia-h100-80gb-hbm3/tables.json")
H200_REPORT = Path("docs/benchmarks/gpu-check/nvidia-h200/tables.json")
"""The GPU checks' stored reports (``sray gpu-check``)."""
SHIPPED = ("hour-recipe", "hour-intra-uncapped")
"""(study, arm) of ``synth-cpu-hour`` as it ships: trained until its CPU budget is spent, seeds 0-2."""
REPEATED = ("hour-budget", "hour-intra-uncapped")
"""The same recipe and seeds repeated on a host where a CPU second bought more ray steps."""
TWICE = ("hour-budget", "hour-2x")
"""The recipe at twice its CPU budget."""
FLEETS = ("from-hour-budget", "from-hour-recipe-hosts", "from-lr-decay-at-the-hour")
"""Arms of study ``finetune-60s``: the 60 s S-Ray finetune of three seed-0 models of the shipped recipe (each named
after the study holding the model's pretraining trial)."""
DEMO = ("demo", "make-demo")
"""(study, arm) of ``make demo`` as it ships (``sray lab demo-result``): the ``synth-demo`` card and the demo's time."""
SHIFTED_SPLITS = {"zero_shot_appearance": "appearance-shifted zero-shot mIoU",
                  "zero_shot_geometry": "geometry-shifted zero-shot mIoU"}
"""Stored split -> its card column, beside the in-distribution zero-shot (``sray data synth --split``): "not stored"
until a study scores the recipe as it ships on those rooms."""
STUDY_PAGES = Path("docs/studies")
"""Where the studies' generated pages are (``sray lab study --page``)."""


def _link(repo_path: Path | str) -> str:
    return f"[`{repo_path}`]({repo_path})"


def _fleet_60s(repo: Path) -> list[float]:
    return [figure(t, "metrics.fleet.sray.miou_at_seconds.60") for arm in FLEETS for t in trials(repo, "finetune-60s",
                                                                                                   arm)]


def machine_label(machine: dict) -> str:
    """A stored machine descriptor as the cards name machines: ``2-core CPU``, else its device."""
    return f"{machine['cores']}-core CPU" if machine.get("device") == "cpu" else str(machine.get("device"))


def _cell(runs: list[dict], dotted: str, show: Callable[[list[float]], str]) -> str:
    """``show`` of the runs' stored values of ``dotted``; ``not stored`` when none holds one."""
    values = present(runs, dotted)
    return show(values) if values else "not stored"


def demo_row(machine: str, runs: list[dict]) -> list[str]:
    """The ``synth-demo`` card on ``machine`` from its stored ``make demo`` runs (mean ± sample sd over seeds)."""
    def minutes(seconds: list[float]) -> str:
        return f"{spread([s / 60 for s in seconds], 1)} min"

    return ["synth-demo", machine, _cell(runs, "trained.wall_seconds", minutes),
            _cell(runs, "trained.cpu_seconds", minutes),
            _cell(runs, "trained.peak_memory_gib", lambda v: f"{spread(v, 1)} GiB"),
            _cell(runs, "metrics.zero_shot.miou", lambda v: f"{spread(v, 1)}% ({seeds(runs)})"), "not measured",
            _cell(runs, "metrics.fleet.sray.miou", lambda v: f"{spread(v, 1)}%"),
            _cell(runs, "metrics.render.seconds_per_frame", lambda v: f"{spread(v, 2)} wall s / frame (fly-through)")]


def demo_note(machine: str, runs: list[dict]) -> str:
    """What the ``synth-demo`` row on ``machine`` shows, with every method of the demo's fleet."""
    fleet = runs[0]["metrics"]["fleet"]
    methods = ", ".join(f"`{m}` " + _cell(runs, f"metrics.fleet.{m}.miou", lambda v: f"{spread(v, 1)}%")
                        for m in fleet)
    return (f"`synth-demo` on the {machine}: `make demo` as it ships ({seeds(runs)}, stored by `sray lab "
            "demo-result`): pretraining from its training job's counters, zero-shot mIoU on its unseen rooms in the "
            f"demo's protocol, the finetune column S-Ray's after the demo's fleet ({fleet['sray']['budget']} on "
            f"{', '.join(fleet['sray']['rooms'])}: {methods}), the render column its fly-through's wall time per "
            "frame.")


def recipe_cards(repo: Path) -> str:
    """The recipe cards: the stored cards of ``sray lab recipe-cards``, with ``synth-cpu-hour`` on the 2-core CPU
    shown as it ships (its stored seeds trained until the budget is spent) instead of the capped cell stored there."""
    data = json.loads((repo / CARDS_DATA).read_text())
    table = next(b for b in data["tables"][0]["blocks"] if "header" in b)
    shipped = trials(repo, *SHIPPED)
    zs, ho = present(shipped, "metrics.zero_shot.miou"), present(shipped, "metrics.held_out.miou")
    walls, cpus = present(shipped, "trained.wall_seconds"), present(shipped, "trained.cpu_seconds")
    memory = present(shipped, "trained.peak_memory_gib")
    fleet = _fleet_60s(repo)
    demos: dict[str, list[dict]] = {}
    for run in trials(repo, *DEMO):
        demos.setdefault(machine_label(run["machine"]), []).append(run)
    rows = []
    for row in table["rows"]:
        shifted = ["—" if row[2].startswith("not run") else "not measured"] * len(SHIFTED_SPLITS)
        if row[0] == "synth-demo" and row[1] in demos:
            row = demo_row(row[1], demos[row[1]])
        if row[0] == "synth-cpu-hour" and row[1] == "2-core CPU":
            row = [row[0], row[1],
                   f"{mean_sd(walls)[0] / 60:.1f} min ({len(walls)} of {len(shipped)} seeds stored)" if walls
                   else "not stored",
                   f"{mean_sd(cpus)[0] / 60:.1f} min", f"{max(memory):.1f} GiB" if memory else "not stored",
                   f"{spread(zs, 1)}%", f"{spread(ho, 1)}%", f"{spread(fleet, 1)}% ({len(fleet)} seed-0 models)",
                   row[8]]
            shifted = [_cell([t for t in shipped if split in t["metrics"]], f"metrics.{split}.miou",
                             lambda v: f"{spread(v, 1)}%") for split in SHIFTED_SPLITS]
        rows.append([*row[:6], *shifted, *row[6:]])
    header = [*table["header"][:6], *SHIFTED_SPLITS.values(), *table["header"][6:]]
    sources = ", ".join(_link(p) for p in [CARDS_DATA, RESULTS / SHIPPED[0], RESULTS / "finetune-60s",
                                           RESULTS / DEMO[0]])
    study = _link(STUDY_PAGES / f"{SHIPPED[0]}.md")
    return (markdown_table(header, rows) + "\n\n"
            f"`synth-cpu-hour` on the 2-core CPU: mean ± sample sd over {seeds(shipped)} of the recipe as it ships "
            f"(trained until its CPU budget is spent; {study}); its render time is its network's, measured on the same "
            f"network at a step cap; its shifted columns are its zero-shot on the generator's held-out appearance and "
            f"geometry regions (`sray data synth --split`). " +
            "".join(f"{demo_note(m, runs)} " for m, runs in demos.items()) +
            f"The other rows as `sray lab recipe-cards` stored them. Read from {sources}.")


def hour_recipe(repo: Path) -> str:
    """The shipped recipe's headline: zero-shot and held-out mIoU over its seeds, repeated on a faster host, and at
    twice its budget."""
    shipped, repeated, twice = trials(repo, *SHIPPED), trials(repo, *REPEATED), trials(repo, *TWICE)

    def scores(ts: list[dict]) -> str:
        return (f"**{spread(present(ts, 'metrics.zero_shot.miou'))}%** zero-shot and "
                f"**{spread(present(ts, 'metrics.held_out.miou'))}%** on held-out views of its training rooms")

    def steps(ts: list[dict]) -> str:
        got = present(ts, "trained.ray_steps")
        return f"{min(got):,.0f}-{max(got):,.0f}"

    return (f"Trained until its CPU budget is spent, `synth-cpu-hour` scores {scores(shipped)} ({seeds(shipped)}, "
            f"{steps(shipped)} ray steps; mean ± sample sd). The same seeds on a host where the same CPU seconds "
            f"bought {steps(repeated)} ray steps score {scores(repeated)}. At twice its budget ({seeds(twice)}) it "
            f"scores {scores(twice)}. Read from {_link(RESULTS / SHIPPED[0])} and {_link(RESULTS / TWICE[0])} "
            f"(pages: {_link(STUDY_PAGES / f'{SHIPPED[0]}.md')}, {_link(STUDY_PAGES / f'{TWICE[0]}.md')}).")


def gpu_training(repo: Path) -> str:
    """The GPU checks' training and render stages as stored: one row per GPU and stage."""
    rows = []
    for path in (H100_REPORT, H200_REPORT):
        data = json.loads((repo / path).read_text())
        stages = next(b for t in data["tables"] for b in t["blocks"] if b.get("header", [None])[0] == "stage")
        rows += [[data["device"], r[0], r[3]] for r in stages["rows"] if r[0] in ("training", "recipe", "bench")]
    return (markdown_table(["GPU", "gpu-check stage", "measured"], rows) + "\n\n"
            f"Read from {_link(H100_REPORT)} and {_link(H200_REPORT)}.")


def demo_time(repo: Path) -> str:
    """The demo's wall time on the 2-core CPU, as its runs stored it."""
    walls = present(trials(repo, *DEMO), "metrics.demo.wall_seconds")
    minutes = " and ".join(f"{wall / 60:.1f}" for wall in walls)
    count = "1 run" if len(walls) == 1 else f"{len(walls)} runs"
    return (f"On the 2-core CPU the demo took {minutes} minutes in {count} on a fresh clone, plus the venv "
            f"set-up (read from {_link(RESULTS / 'demo')}).")


CAPTURE_SCALE = Path("docs/capture_scale.json")
"""The capture readers' measured scale and bounds errors (``tests/capture_scale_check.py``)."""


def capture_scale(repo: Path) -> str:
    """The capture readers' scale error per point-noise level, and how much wider the bounds from points alone were
    than those from the depth maps, as stored."""
    rows = json.loads((repo / CAPTURE_SCALE).read_text())["rows"]
    noises = sorted({r["point_noise"] for r in rows})

    def span(values: list[float], digits: int) -> str:
        return f"{min(values):.{digits}f} to {max(values):.{digits}f}"

    below = [f"{span([-100 * r['relative_error'] for r in rows if r['point_noise'] == n], 2)}% below with "
             f"{100 * n:g}% noise" for n in noises]
    near = [100 * (1 - r["near_far_from_points"][0] / r["near_far_from_depth"][0]) for r in rows]
    far = [100 * (r["near_far_from_points"][1] / r["near_far_from_depth"][1] - 1) for r in rows]
    return (f"The measured scale was {'; '.join(below)} ({len(rows) // len(noises)} rooms per level). Bounds from the "
            f"points alone were wider than those from the depth maps: near {span(near, 0)}% lower, far "
            f"{span(far, 0)}% higher. Read from {_link(CAPTURE_SCALE)}.")


RENDERERS: dict[str, Callable[[Path], str]] = {
    "recipe-cards": recipe_cards,
    "hour-recipe": hour_recipe,
    "gpu-training": gpu_training,
    "demo-time": demo_time,
    "capture-scale": capture_scale,
    "appearance-step-cost": appearance_step_cost,
}
"""Block name -> its renderer (a function of the repository folder)."""
