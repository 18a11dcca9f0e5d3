"""The shift gap of a study: per trial, its in-distribution zero-shot mIoU minus its mIoU on the appearance- and on
the geometry-shifted test rooms (points), with each arm's mean and seed spread, and the headline: the gaps of the arm
chosen on the selection split (the page's first section when the study scores shifted splits)."""

from __future__ import annotations

from typing import Any

from sray.lab.studies.paired import by_arm_and_seed, mean_and_std
from sray.lab.studies.results import metric
from sray.lab.studies.splits import SHIFTED, TEST_SPLITS
from sray.lab.studies.spec import StudySpec
from sray.platform.common.doc_blocks import markdown_table

GAP_LABELS = {"zero_shot_appearance": "appearance", "zero_shot_geometry": "geometry"}
"""How the page names each shifted split's gap."""


def gaps(results: dict[str, dict[str, Any]], split: str) -> dict[str, dict[int, float]]:
    """arm -> seed -> ``zero_shot`` mIoU minus ``split`` mIoU of the same trial (points), trials holding both."""
    table: dict[str, dict[int, float]] = {}
    for result in results.values():
        reference, shifted = metric(result, "zero_shot"), metric(result, split)
        if reference is not None and shifted is not None:
            table.setdefault(result["arm"], {})[int(result["seed"])] = reference - shifted
    return table


def _pm(values: list[float]) -> str:
    mean, std = mean_and_std(values)
    return "—" if mean is None else f"{mean:.2f}" + ("" if std is None else f" ± {std:.2f}") + f" ({len(values)})"


def chosen_arm(spec: StudySpec, results: dict[str, dict[str, Any]]) -> str:
    """The arm with the highest mean mIoU on the study's selection split (the baseline when none has a score)."""
    means = {arm: mean_and_std(list(seeds.values()))[0] for arm, seeds in
             by_arm_and_seed(results, spec.select_on).items() if arm in spec.arms}
    return max(means, key=lambda arm: (means[arm], arm == spec.baseline)) if means else spec.baseline


def gap_section(spec: StudySpec, results: dict[str, dict[str, Any]]) -> list[str]:
    """The page's "Shift gap" lines: the headline sentence and one row per arm (the three test splits side by side,
    then each gap, mean ± sample std over seeds); empty when no trial holds a shifted split."""
    table = {split: gaps(results, split) for split in SHIFTED}
    if not any(table.values()):
        return []
    chosen = chosen_arm(spec, results)
    said = [f"{GAP_LABELS[s]}-shifted {_pm(list(table[s].get(chosen, {}).values()))} points" for s in SHIFTED]
    scores = {s: by_arm_and_seed(results, s) for s in TEST_SPLITS}
    rows = [[f"**{arm}**" if arm == chosen else arm,
             *[_pm(list(scores[s].get(arm, {}).values())) for s in TEST_SPLITS],
             *[_pm(list(table[s].get(arm, {}).values())) for s in SHIFTED]] for arm in spec.arms]
    header = ["arm", "in-distribution mIoU %", "appearance-shifted mIoU %", "geometry-shifted mIoU %",
              *[f"{GAP_LABELS[s]} gap (points)" for s in SHIFTED]]
    return ["## Shift gap", "",
            f"**Headline: arm {chosen} (chosen on the {spec.select_on} rooms) loses {said[0]} and {said[1]} from "
            "in-distribution** (each trial's in-distribution mIoU minus its shifted mIoU; mean ± sample std (seeds)).",
            "", markdown_table(header, rows), ""]
