"""The CPU cost of the appearance levers (docs/model.md, "Levers against leaning on the look"), published from the
stored measurement ``jobs/studies/results/appearance-levers/step-cost.json``: one ray step of ``synth-cpu-hour`` per
variant (``sray lab recipe-step``) and the generator's CPU per view with and without appearance randomisation."""

from __future__ import annotations

import json
import statistics
from pathlib import Path

from sray.lab.publish.bench_data import markdown_table
from sray.lab.publish.results import RESULTS, ResultError

STEP_COST = RESULTS / "appearance-levers" / "step-cost.json"
"""The stored measurement, relative to the repository."""
WHOLE_STEP, RATIO = "**whole step at the expected sources**", "step CPU vs the recipe"
"""The rows of the stored recipe-step table the block shows."""


def appearance_step_cost(repo: Path) -> str:
    """A table of each variant's CPU per ray step (at its expected source count) and its ratio to the recipe, then
    the generator's CPU per view at each randomisation strength, the machine and the source file."""
    path = Path(repo) / STEP_COST
    data = json.loads(path.read_text())
    table = data["recipe_step"]["tables"][0]
    block = next(b for b in table["blocks"] if "header" in b)
    rows = {row[0]: row[1:] for row in block["rows"]}
    if WHOLE_STEP not in rows or RATIO not in rows:
        raise ResultError(f"{path}: recipe_step table lacks the rows {WHOLE_STEP!r} and {RATIO!r}; measure it again")
    variants = block["header"][1:]
    steps = markdown_table(["variant", "CPU ms per ray step", "vs the recipe"],
                           [[v, rows[WHOLE_STEP][i].strip("*"), rows[RATIO][i]] for i, v in enumerate(variants)])
    per_view = data["generation"]["cpu_s_per_view"]
    height, width = data["generation"]["hw"]
    views = "; ".join(f"randomise {float(r):g}: {statistics.fmean(v):.3f} CPU s per {width}x{height} view "
                      f"({len(v)} runs)" for r, v in per_view.items())
    machine = data["machine"]
    return (steps + "\n\n"
            f"Generator: {views}. Measured on {machine['cpu_model']}, {machine['cores']} cores "
            f"({table['machine']}), {table['measured_utc']}, commit {data['commit']}; variants: `photometric` "
            "(the per-view augmentation), `cues` (all four appearance-free cues), `both`. Read from "
            f"[`{STEP_COST}`]({STEP_COST}).")
