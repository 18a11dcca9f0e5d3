"""A study's page, ``docs/studies/<study>.md``, generated from its stored results: what was run, the arms' scores with
their seed spread, the paired differences to the baseline arm, every trial, a chart, the levers the product has
since removed, and the hand-written "Reading" (at most :data:`MAX_READING_LINES` lines), which regeneration keeps.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from sray.data_tools.atomic import atomic_write_text
from sray.lab.studies.chart import SPLIT_LABELS, miou_chart
from sray.lab.studies.fleet_ceilings import CEILING_ROOMS
from sray.lab.studies.gap import gap_section
from sray.lab.studies.paired import by_arm_and_seed, mean_and_std, paired_differences
from sray.lab.studies.results import metric, read_results
from sray.lab.studies.spec import StudySpec, assignments
from sray.platform.common.doc_blocks import markdown_table

READING = "## Reading"
MAX_READING_LINES = 15
READING_HINT = "<!-- hand-written, at most 15 lines; `sray lab study --page` keeps this section as it is -->"
"""The first line of a Reading section (not counted)."""


def page_path(spec: StudySpec, docs: Path) -> Path:
    """``<docs>/studies/<study>.md``."""
    return Path(docs) / "studies" / f"{spec.name}.md"


def reading_of(page: Path) -> list[str]:
    """The lines of the page's Reading section (its hint and surrounding blank lines left out); ValueError naming the
    page when they are more than :data:`MAX_READING_LINES`."""
    if not page.is_file():
        return []
    lines = page.read_text().splitlines()
    if READING not in lines:
        return []
    start = lines.index(READING) + 1
    end = next((i for i in range(start, len(lines)) if lines[i].startswith("## ")), len(lines))
    body = [line for line in lines[start:end] if line.strip() != READING_HINT]
    while body and not body[0].strip():
        body.pop(0)
    while body and not body[-1].strip():
        body.pop()
    if len(body) > MAX_READING_LINES:
        raise ValueError(f"{page}: its Reading has {len(body)} lines; shorten it to at most {MAX_READING_LINES} "
                         "(the tables above carry the numbers)")
    return body


def _shown(path: Path) -> str:
    """``path`` relative to the working folder (the repository root) when it lies inside it."""
    try:
        return Path(path).resolve().relative_to(Path.cwd()).as_posix()
    except ValueError:
        return Path(path).as_posix()


def _pm(values: list[float]) -> str:
    mean, std = mean_and_std(values)
    if mean is None:
        return "—"
    return f"{mean:.2f}" + ("" if std is None else f" ± {std:.2f}") + f" ({len(values)})"


def _num(value: Any, digits: int = 0) -> str:
    return "—" if value is None else f"{value:,.{digits}f}"


def arms_table(spec: StudySpec, results: dict[str, dict[str, Any]], splits: list[str]) -> str:
    """One row per arm: its overrides and, per split, mean ± std (seeds) of its mIoU."""
    tables = {s: by_arm_and_seed(results, s) for s in splits}
    rows = []
    for name, arm in spec.arms.items():
        what = ", ".join(f"`{a}`" for a in arm.overrides()) or "the base recipe"
        if arm.world:
            what += "; world " + ", ".join(f"{k} {v}" for k, v in arm.world.items())
        if arm.budget:
            what += f"; budget {arm.budget.describe()}"
        rows.append([f"**{name}**" if name == spec.baseline else name, what,
                     *[_pm(list(tables[s].get(name, {}).values())) for s in splits]])
    return markdown_table(["arm", "overrides", *[f"{SPLIT_LABELS[s]} mIoU %" for s in splits]], rows)


def paired_table(spec: StudySpec, results: dict[str, dict[str, Any]], splits: list[str]) -> str:
    """Per arm and split: the seeds it shares with the baseline, each seed's difference and their mean ± std."""
    rows = []
    order = list(spec.arms)
    for split in splits:
        pairs = paired_differences(results, spec.baseline, split)
        for p in sorted(pairs, key=lambda p: order.index(p.arm) if p.arm in order else len(order)):
            if p.seeds:
                rows.append([p.arm, SPLIT_LABELS[split], ", ".join(map(str, p.seeds)),
                             ", ".join(f"{d:+.2f}" for d in p.differences),
                             f"{p.mean:+.2f}" + ("" if p.std is None else f" ± {p.std:.2f}")])
    return markdown_table(["arm", "split", "shared seeds", f"arm − {spec.baseline} per seed (points)", "mean ± std"],
                          rows) if rows else "No arm shares a seed with the baseline yet."


def trials_table(results: dict[str, dict[str, Any]], splits: list[str]) -> str:
    """Every stored trial: its mIoU per split, what it trained, where and where its numbers come from."""
    rows = [[r["arm"], str(r["seed"]), *[_num(metric(r, s), 2) for s in splits], _num(r["trained"].get("ray_steps")),
             _num(r["trained"].get("cpu_seconds")), r["machine"].get("cpu_model") or "—",
             str(r["machine"].get("cores") or "—"), r["source"]] for r in results.values()]
    return markdown_table(["arm", "seed", *[f"{s} mIoU %" for s in splits], "ray steps", "CPU s", "CPU", "cores",
                           "source"], rows)


def ceilings_section(spec: StudySpec, results: dict[str, dict[str, Any]]) -> list[str]:
    """The page's "Ceilings" lines: one row per ceiling row, per arm the mean ± std (seeds) of its mIoU; empty when no
    trial holds ceilings."""
    blocks = [(r["arm"], r["metrics"]["ceilings"]) for r in results.values() if r["metrics"].get("ceilings")]
    if not blocks:
        return []
    titles, values = {}, {}
    for arm, block in blocks:
        for key, row in block["rows"].items():
            titles.setdefault(key, row)
            if row["miou"] is not None:
                values.setdefault((arm, key), []).append(row["miou"])
    rows = [[key, row["title"], "**oracle**" if row["oracle"] else "no",
             *[_pm(values.get((arm, key), [])) for arm in spec.arms]] for key, row in titles.items()]
    rooms = " and ".join(sorted({CEILING_ROOMS[b["scenes"]] for _, b in blocks}))
    return ["## Ceilings", "", f"The rows of `sray lab ceilings` on each arm's own world, {rooms} (mIoU %, mean ± "
            "sample std (seeds); oracle rows read the query view's ground truth): "
            f"{blocks[0][1]['protocol']}.", "", markdown_table(["row", "what", "oracle", *spec.arms], rows), ""]


def render_page(spec: StudySpec, results: dict[str, dict[str, Any]], reading: list[str], chart: str | None) -> str:
    """The page's Markdown."""
    splits = [s for s in SPLIT_LABELS if by_arm_and_seed(results, s)]
    chosen = [r for r in results.values() if metric(r, spec.select_on) is not None]
    val = spec.validation_world()
    common = "; every arm: " + ", ".join(f"`{a}`" for a in assignments(spec.sets)) if spec.sets else ""
    lines = [f"# Study: {spec.name}", "",
             f"<!-- generated by `sray lab study --page {_shown(spec.path)}` from "
             f"{f'{_shown(spec.results_dir)}/' if spec.results_dir.is_dir() else 'no stored result yet'}; "
             "edit only the Reading -->", "",
             spec.description, "",
             f"Base recipe `{spec.recipe}`{common}. World: {spec.world.train_scenes} training rooms, "
             f"{spec.world.test_scenes} test rooms, "
             f"{spec.world.views} views of {spec.world.width}x{spec.world.height}, seed {spec.world.seed}. "
             + ("" if spec.split_rooms is None else
                f"Test splits: {spec.split_rooms} rooms each, in-distribution, appearance-shifted and geometry-shifted "
                "(the world's seed and sizes, no training room; docs/data.md, \"Shifted test splits\"). ")
             + ("" if spec.calibration_stride is None else
                "The fast render's confidence temperature is fitted per trial on the validation rooms. ")
             + ("" if spec.fleet is None else "Fleet: the last checkpoint finetuned with S-Ray on "
                + (f"the first {spec.fleet.rooms} test room(s)" if spec.fleet.rooms else "every test room")
                + f", {spec.fleet.describe()}, as `sray finetune-fleet` does. ") +
             f"Budget per trial: {spec.budget.describe()}. Seeds: {', '.join(map(str, spec.seeds))}. "
             f"{len(results)} of {len(spec.trial_keys())} trials stored.", "",
             f"**Selection split: {spec.select_on}.** Arms are chosen on the {SPLIT_LABELS[spec.select_on]} "
             f"(validation: {val.test_scenes} room(s) of world seed {val.seed}"
             + ("" if val.split == "in-distribution" else f", the generator's {val.split} stream")
             + ", no result is reported on them); "
             "the test rooms only report."
             + ("" if len(chosen) == len(results) else
                f" {len(results) - len(chosen)} stored trial(s) hold no {spec.select_on} score (made before the study "
                "had a validation split): the choices they record were made on the test rooms."), "",
             *gap_section(spec, results),
             "## Arms", "", "mean ± sample std (seeds) of each arm's mIoU; the baseline arm in bold.", "",
             arms_table(spec, results, splits), "",
             f"## Paired differences (arm − {spec.baseline})", "", paired_table(spec, results, splits), ""]
    if chart:
        lines += [f"![mIoU per arm]({chart})", ""]
    removed = [a for a in spec.arms.values() if a.removed_after]
    if removed:
        lines += ["## Removed from the product", "",
                  markdown_table(["arm", "overrides", "last commit that had it", "note"],
                                 [[a.name, ", ".join(f"`{o}`" for o in a.overrides()),
                                   f"removed from the product after {a.removed_after}", a.note or "—"]
                                  for a in removed]), ""]
    lines += [*ceilings_section(spec, results), "## Trials", "", trials_table(results, splits), "", READING, "",
              READING_HINT, *reading]
    return "\n".join(lines).rstrip() + "\n"


def write_page(spec: StudySpec, docs: Path) -> Path:
    """Regenerate the study's page and chart from its stored results, keeping the page's Reading; the page."""
    page = page_path(spec, docs)
    reading = reading_of(page)
    results = read_results(spec.results_dir)
    chart = miou_chart(results, list(spec.arms), page.parent / spec.name / "miou.png", f"{spec.name}: mIoU per arm")
    atomic_write_text(page, render_page(spec, results, reading, None if chart is None else f"{spec.name}/miou.png"))
    return page
