"""``sray bench speed-accuracy``'s per-class accounting, rule column and verdicts, on hand-made rows and a
hand-made confusion matrix (no rendering)."""

from __future__ import annotations

import pytest

from sray.jobs.bench.speed_accuracy import table
from sray.model.fast_render import FastRender


def _row(name: str, miou: float, s: float, fast: bool = False) -> dict:
    return {"name": name, "method": "sray", "inputs": "rgb", "miou": miou, "psnr": 20.0, "s_per_view": s, "views": 4,
            "setting": {"fast": {"pixel_stride": 4} if fast else None}}


def test_class_scores_of_a_hand_made_confusion_matrix() -> None:
    """IoU = TP / (ground truth + predicted - TP) per class, in %, None for a class absent from the ground truth;
    shares are ground-truth rows over all labelled pixels."""
    import torch

    from sray.jobs.bench.speed_classes import class_scores

    conf = torch.tensor([[8, 2, 0], [1, 4, 0], [0, 0, 0]])  # rows: ground truth, columns: prediction
    ious, shares = class_scores(conf)
    assert ious[0] == pytest.approx(100 * 8 / 11) and ious[1] == pytest.approx(100 * 4 / 7) and ious[2] is None
    assert shares == pytest.approx([10 / 15, 5 / 15, 0.0])
    assert class_scores(torch.zeros(2, 2, dtype=torch.int64)) == ([None, None], [0.0, 0.0])


def _class_row(name: str, miou: float, s: float, ious: list, fast: bool = False) -> dict:
    return _row(name, miou, s, fast) | {"wall_s_per_view": s / 2, "class_names": ["wall", "chair", "lamp"],
                                        "class_iou": ious, "class_share": [0.7, 0.295, 0.005]}


CLASS_ROWS = [_class_row("full", 50.0, 40.0, [80.0, 30.0, 20.0]), _class_row("fast a", 49.5, 1.0, [80.0, 28.0, 0.0]),
              _class_row("fast b", 49.8, 0.5, [81.0, 25.0, 20.0])]


def test_class_table_shows_the_counted_classes_their_share_and_paired_differences() -> None:
    from sray.jobs.bench.speed_classes import class_table

    lines = [[c.strip() for c in ln.split("|")] for ln in class_table(CLASS_ROWS, chosen="fast a").splitlines()]
    assert lines[0] == ["IoU % (Δ vs first row, points)", "wall", "chair"]  # lamp holds 0.5%: not shown
    assert lines[2] == ["share of labelled test pixels", "70.0%", "29.5%"]
    assert lines[3] == ["full", "80.0 (+0.0)", "30.0 (+0.0)"]
    assert lines[4] == ["**fast a** (chosen)", "80.0 (+0.0)", "28.0 (-2.0)"]


def test_the_rule_column_and_the_verdict_table_say_what_was_chosen_and_why_the_faster_ones_were_not() -> None:
    """The bench's rows go through the rule: 'fast b' is fastest but loses 5 points on chair; 'fast a' passes;
    today's sray eval default is 'fast b' here, validation's was not measured."""
    from sray.jobs.bench.speed_accuracy import Setting
    from sray.jobs.bench.speed_verdict import rule_choice, verdict_table

    settings = [Setting("full"), Setting("fast a", fast=FastRender(4, 0.9)), Setting("fast b", fast=FastRender()),
                Setting("4 sources", n_source=4)]
    rows = [*CLASS_ROWS, _class_row("4 sources", 10.0, 0.1, [10.0, 1.0, 0.0])]
    choice = rule_choice(rows, settings)
    assert choice.chosen == "fast a" and "4 sources" not in choice.shortfalls  # evaluates otherwise: not offered
    cells = {ln.split("|")[1].strip(): ln.split("|")[-2].strip() for ln in table(rows, choice).splitlines()[2:]}
    assert cells == {"full": "reference", "fast a": "**chosen**", "fast b": "✗ chair -5.00", "4 sources": "not offered"}
    today = {"sray eval": "fast b", "validation": None}
    [_, _, line] = verdict_table(["ckpt-0"], [choice], today).splitlines()
    verdict = "sray eval (fast b): fails (chair -5.00); validation: not measured"
    assert [c.strip() for c in line.split("|")] == ["ckpt-0", "fast a", "fast b: chair -5.00", verdict]
    assert rule_choice(rows[1:], settings[1:]) is None  # the first row is no full render: no reference


def test_mean_rows_average_each_setting_over_the_checkpoints() -> None:
    from sray.jobs.bench.speed_classes import mean_rows

    other = [r | {"miou": r["miou"] + 2.0, "s_per_view": 3 * r["s_per_view"],
                  "class_iou": [None if i == 2 else v + 1.0 for i, v in enumerate(r["class_iou"])]} for r in CLASS_ROWS]
    mean = mean_rows([CLASS_ROWS, other])
    assert [r["name"] for r in mean] == ["full", "fast a", "fast b"] and mean[0]["checkpoints"] == 2
    assert mean[1]["miou"] == pytest.approx(50.5) and mean[1]["s_per_view"] == pytest.approx(2.0)
    assert mean[1]["class_iou"] == [pytest.approx(80.5), pytest.approx(28.5), None]  # absent in one run: no mean
    with pytest.raises(ValueError, match="other settings"):
        mean_rows([CLASS_ROWS, CLASS_ROWS[:2]])


def test_the_rule_never_offers_another_methods_row() -> None:
    """A 2d-transfer row faster than every setting and losing nothing is neither chosen nor judged; the table marks
    it as another method and shows its inputs."""
    from sray.jobs.bench.speed_accuracy import Setting
    from sray.jobs.bench.speed_verdict import rule_choice

    settings = [Setting("full"), Setting("fast a", fast=FastRender(4, 0.9)), Setting("fast b", fast=FastRender())]
    transfer = _class_row("2d-transfer", 60.0, 0.01, [90.0, 40.0, 20.0]) | {"method": "2d-transfer",
                                                                             "inputs": "rgbd", "setting": None}
    rows = [*CLASS_ROWS, transfer]
    choice = rule_choice(rows, settings)
    assert choice.chosen == "fast a" and "2d-transfer" not in choice.shortfalls
    cells = {ln.split("|")[1].strip(): [c.strip() for c in ln.split("|")[1:-1]] for ln in
             table(rows, choice).splitlines()[2:]}
    assert cells["2d-transfer"][1] == "RGB-D" and cells["2d-transfer"][-1] == "another method"
    assert cells["fast a"][-1] == "**chosen**"
