"""A study's ``fleet`` and ``ceilings`` evaluations: a wrong setting is one error naming the file, the field and the
fix; a trial (training and world generation stubbed, its room splits' evaluation stubbed as test_lab_study_splits.py
does) finetunes the tiny checkpoint on the test room on local Ray and scores its ceiling rows, the stored blocks
checked against the product's own finetune of that room and lab/ceilings' own report; the page shows both."""

from __future__ import annotations

from pathlib import Path

import pytest
from fleet_fixtures import one_thread, tiny_checkpoint  # noqa: F401
from mlflow_fixtures import mlflow_template, mlflow_uri  # noqa: F401
from train_fixtures import tiny_shards  # noqa: F401

from sray.lab.ceilings.measure import measure_ceilings
from sray.lab.studies import trial
from sray.lab.studies.page import write_page
from sray.lab.studies.results import read_results, write_result
from sray.lab.studies.spec import StudyError, load_study
from sray.model.fast_render import FastRender
from sray.platform.finetune.scene_artifacts import checkpoint_sha256
from sray.platform.finetune.scene_finetune import SceneTask, finetune_scene

SPEC = """study: evals
description: What does a per-room finetune add, and where is accuracy lost?
recipe: synth-small
world: {train_scenes: 2, test_scenes: 1, views: 20, height: 32, width: 40}
validation: {seed: 5, rooms: 1}
arms:
  base: {}
  lr-2x: {optim.lr: 0.002}
seeds: [0]
budget: {steps: 4}
evaluations: [zero_shot, validation, fleet, ceilings]
fleet: {cpu_seconds: 600, steps: 4, rooms: 2}
ceilings: {views: 1, probe_steps: 2, probe_views: 4}
eval: {sources: 4}
"""


def _spec(tmp_path: Path, text: str = SPEC) -> Path:
    path = tmp_path / "studies" / "evals.yaml"
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text)
    return path


@pytest.mark.parametrize("change, field, fix", [
    (("fleet: {cpu_seconds: 600,", "fleet: {"), "fleet", "give fleet: {cpu_seconds: 60}"),
    (("fleet: {cpu_seconds: 600, steps: 4, rooms: 2}\n", ""), "fleet", "give fleet: {cpu_seconds: 60}"),
    (("cpu_seconds: 600,", "cpu_seconds: -1,"), "fleet.cpu_seconds", "write e.g. 60"),
    (("steps: 4,", "steps: 2.5,"), "fleet.steps", "write e.g. 4"),
    (("rooms: 2}", "scenes: 2}"), "fleet.scenes", "fleet takes cpu_seconds, seconds, steps, rooms"),
    (("ceilings: {views: 1,", "ceilings: {scenes: validation, views: 1,"), "ceilings.scenes",
     "write one of test, held_out"),
    (("probe_steps: 2,", "probe_steps: 0,"), "ceilings.probe_steps", "write e.g. 4"),
    (("validation, fleet, ceilings]", "validation, ceilings]"), "fleet", "add fleet to evaluations or drop the key"),
    (("ceilings: {views: 1, probe_steps: 2, probe_views: 4}", "ceilings: [1, 2]"), "ceilings",
     "write ceilings: {scenes: ...}"),
])
def test_a_wrong_fleet_or_ceilings_setting_is_one_error_naming_the_file_the_field_and_the_fix(
        tmp_path: Path, change: tuple, field: str, fix: str) -> None:
    path = _spec(tmp_path, SPEC.replace(*change))
    with pytest.raises(StudyError) as caught:
        load_study(path)
    assert str(caught.value).startswith(f"{path}: {field}:") and fix in str(caught.value)


def test_a_trial_stores_the_fleet_and_the_ceilings_as_the_product_and_the_lab_measure_them(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch, ray_session: dict, tiny_shards: Path,  # noqa: F811
        tiny_checkpoint: Path, mlflow_uri: str, one_thread: None) -> None:  # noqa: F811
    spec = load_study(_spec(tmp_path))
    assert spec.fleet.describe() == "600 CPU s or 4 steps per room" and spec.ceilings.scenes == "test"
    monkeypatch.setattr(trial, "make_world", lambda world, root, progress: tiny_shards)
    monkeypatch.setattr(trial, "train", lambda cfg: tiny_checkpoint)
    monkeypatch.setattr(trial, "evaluate_checkpoint", lambda checkpoint, folder, scenes, out_dir, **kw: {})
    monkeypatch.setattr(trial, "split_metrics", lambda report, folder, scenes: {"miou": 10.0, "rooms": len(scenes)})
    result = trial.run_trial(spec, "base", 0, tmp_path / "out" / "evals", mlflow_uri)
    assert read_results(spec.results_dir)["base--s0"] == result

    fleet = result["metrics"]["fleet"]["sray"]
    task = SceneTask(scene="synth_test_000", method="sray", checkpoint=str(tiny_checkpoint),
                     base_sha256=checkpoint_sha256(tiny_checkpoint), shards=str(tiny_shards),
                     out_dir=str(tmp_path / "alone"), run=None, attempt=1, config=spec.fleet.config("alone", 4))
    alone = finetune_scene(task).result  # the product's finetune of the same room, in this process
    assert fleet["miou"] == round(100 * alone["miou_after"], 2) and fleet["steps"] == alone["steps_used"] == 4
    assert fleet["miou_before"] == round(100 * alone["miou_before"], 2) and fleet["rooms"] == ["synth_test_000"]
    assert fleet["stopped_by"] == ["max_steps"] and fleet["budget"] == "600 CPU s or 4 steps per room"
    assert "sources: 4 per query" in fleet["protocol"]

    ceilings = result["metrics"]["ceilings"]
    report = measure_ceilings(tiny_checkpoint, tiny_shards, n_source=4, views_per_scene=1, probe_steps=2,
                              probe_views=4, render=FastRender(pixel_stride=1, confidence=0.9), progress=False)
    assert list(ceilings["rows"]) == [r["key"] for r in report["rows"]] == ["a", "s", "d", "e", "e-rand"]
    for row in report["rows"]:
        stored = ceilings["rows"][row["key"]]
        assert stored["miou"] == round(100 * row["miou"], 2) and stored["oracle"] == row["oracle"]
        assert stored["coverage"] == (None if row["coverage"] is None else round(100 * row["coverage"], 2))
    assert (ceilings["rooms"], ceilings["views"], ceilings["scenes"]) == (1, 1, "test")
    assert (tmp_path / "out" / "evals" / "eval" / "ceilings" / "evals-base-s0" / "ceilings.json").is_file()

    other = result | {"arm": "lr-2x", "metrics": {**result["metrics"], "fleet": {"sray": {**fleet, "miou": 50.0}}}}
    write_result(spec.results_dir, other)
    text = write_page(spec, tmp_path / "docs").read_text()
    assert "S-Ray on the first 2 test room(s), 600 CPU s or 4 steps per room, as `sray finetune-fleet` does" in text
    assert f"| {fleet['miou']:.2f} (1)\n" in text and "| 50.00 (1)\n" in text  # the arms table's fleet column
    assert f"lr-2x | test rooms after a per-room S-Ray finetune | 0 | {50.0 - fleet['miou']:+.2f}" in text
    row_s = ceilings["rows"]["s"]["miou"]
    assert "## Ceilings" in text and f"s | S-Ray zero-shot render | no | {row_s:.2f} (1) | {row_s:.2f} (1)\n" in text


def test_a_rerun_trial_scores_only_what_its_stopped_run_left_and_a_new_protocol_scores_again(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch, tiny_shards: Path,  # noqa: F811
        tiny_checkpoint: Path, mlflow_uri: str, one_thread: None) -> None:  # noqa: F811
    text = SPEC.replace("evaluations: [zero_shot, validation, fleet, ceilings]", "evaluations: [zero_shot, validation]")
    text = text.split("fleet: {")[0] + "calibration: {stride: 4}\neval: {sources: 4, confidence: 0.9}\n"
    spec = load_study(_spec(tmp_path, text))
    out, calls = tmp_path / "out" / "evals", []
    evaluate, calibrate = trial.evaluate_checkpoint, trial.calibrate
    monkeypatch.setattr(trial, "make_world", lambda world, root, progress: tiny_shards)
    monkeypatch.setattr(trial, "train", lambda cfg: tiny_checkpoint)
    monkeypatch.setattr(trial, "evaluate_checkpoint",
                        lambda *a, **kw: calls.append(a[3].parent.name) or evaluate(*a, **kw))
    monkeypatch.setattr(trial, "calibrate", lambda *a: calls.append("calibration") or calibrate(*a))
    first = trial.run_trial(spec, "base", 0, out, mlflow_uri)
    assert calls == ["calibration", "zero_shot", "validation"]

    (out / "eval" / "validation" / "evals-base-s0" / "metrics.json").unlink()  # stopped while scoring validation
    calls.clear()
    assert trial.run_trial(spec, "base", 0, out, mlflow_uri)["metrics"] == first["metrics"]
    assert calls == ["validation"]

    calls.clear()  # the same checkpoint at another confidence: same temperature fit, new scores
    other = load_study(_spec(tmp_path, text.replace("confidence: 0.9", "confidence: 0.5")))
    assert trial.run_trial(other, "base", 0, out, mlflow_uri)["metrics"]["zero_shot"]["protocol"] != \
        first["metrics"]["zero_shot"]["protocol"]
    assert calls == ["zero_shot", "validation"]
