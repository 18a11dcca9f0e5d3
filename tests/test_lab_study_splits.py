"""Studies with shifted test splits (``splits``, a validation stream, ``calibration``): the spec's checks, and a trial
(training, world generation and evaluation stubbed, as test_lab_studies.py stubs the trial) scoring every test split
on its own world, storing them as the result's metrics, and the page showing them side by side with the gap."""

from __future__ import annotations

import statistics
from pathlib import Path

import pytest

from sray.data_tools.synth.world import SPLIT_RESULTS
from sray.lab.studies import trial
from sray.lab.studies.page import write_page
from sray.lab.studies.results import read_results
from sray.lab.studies.spec import StudyError, load_study

SPEC = """study: shift
description: Does randomising the look close the gap?
recipe: synth-small
world: {train_scenes: 2, test_scenes: 1, views: 20, height: 24, width: 32}
splits: {rooms: 16}
validation: {split: validation, rooms: 16}
calibration: {stride: 2}
baseline: base
arms:
  base: {}
  rand: {set: {}, world: {randomise: 1.0}}
seeds: [0, 1]
budget: {steps: 4}
evaluations: [zero_shot, zero_shot_appearance, zero_shot_geometry, held_out, validation]
"""
MIOU = {  # (arm, seed) -> split -> mIoU (fraction) the stubbed evaluation reports
    ("base", 0): {"zero_shot": 0.60, "zero_shot_appearance": 0.40, "zero_shot_geometry": 0.55, "held_out": 0.7,
                  "validation": 0.58},
    ("base", 1): {"zero_shot": 0.62, "zero_shot_appearance": 0.38, "zero_shot_geometry": 0.50, "held_out": 0.7,
                  "validation": 0.59},
    ("rand", 0): {"zero_shot": 0.61, "zero_shot_appearance": 0.55, "zero_shot_geometry": 0.56, "held_out": 0.7,
                  "validation": 0.63},
    ("rand", 1): {"zero_shot": 0.59, "zero_shot_appearance": 0.50, "zero_shot_geometry": 0.52, "held_out": 0.7,
                  "validation": 0.60},
}


def _spec(tmp_path: Path, text: str = SPEC) -> Path:
    path = tmp_path / "studies" / "shift.yaml"
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text)
    return path


WRONG = {  # field -> (the edit of SPEC that breaks it, a fragment of the fix its error must name)
    "splits": (("splits: {rooms: 16}\n", ""), "add splits: {rooms: 16}"),
    "splits.rooms": (("splits: {rooms: 16}", "splits: {rooms: 4}"), "an integer >= 16"),
    "validation.split": (("split: validation, rooms", "split: appearance-shift, rooms"), "write split: validation"),
    "world.split": (("width: 32}", "width: 32, split: geometry-shift}"), "list the test splits in evaluations"),
    "arms.rand.world.randomise": (("randomise: 1.0", "randomise: 2"), "in [0, 1]"),
    "calibration": (("calibration: {stride: 2}", "calibration: {stride: 2}\neval: {render: full}"),
                    "drop calibration or evaluate with render: fast"),
}


def test_a_wrong_split_field_is_one_error_naming_the_file_the_field_and_the_fix(tmp_path: Path) -> None:
    for field, (change, fix) in WRONG.items():
        path = _spec(tmp_path, SPEC.replace(*change))
        with pytest.raises(StudyError) as caught:
            load_study(path)
        assert str(caught.value).startswith(f"{path}: {field}:") and fix in str(caught.value), field


def test_a_trial_scores_each_split_on_its_own_world_and_the_page_shows_the_gap(tmp_path: Path,
                                                                               monkeypatch: pytest.MonkeyPatch) -> None:
    spec = load_study(_spec(tmp_path))
    made: dict[Path, object] = {}
    seen: dict[tuple[str, str], tuple] = {}

    def make_world(world, root: Path, progress: bool) -> Path:
        made[root / "shards"] = world
        return root / "shards"

    def evaluate(checkpoint, folder, scenes, out_dir, n_source, tracking_uri, experiment, progress, fast):
        split, run = out_dir.parent.name, out_dir.name
        seen[(run, split)] = (made[folder], scenes, fast.temperature)
        arm, seed = run.split("-")[1], int(run[-1])
        return {"mean": {"dataset_level": {"miou": MIOU[(arm, seed)][split]}}}

    monkeypatch.setattr(trial, "make_world", make_world)
    monkeypatch.setattr(trial, "train", lambda cfg: tmp_path / "ckpt" / cfg.run.name)
    monkeypatch.setattr(trial, "select_scenes", lambda folder, scenes: ([f"test{i}" for i in range(3)], {}))
    monkeypatch.setattr(trial, "training_scenes", lambda folder, n: ["train0"])
    monkeypatch.setattr(trial, "checkpoint_model", lambda checkpoint, fast: ("model", checkpoint))
    monkeypatch.setattr(trial, "calibrate", lambda model, val, n_source, stride: {"temperature": 1.5 + stride,
                                                                                  "shards": str(val)})
    monkeypatch.setattr(trial, "evaluate_checkpoint", evaluate)
    monkeypatch.setattr(trial, "split_metrics", lambda report, folder, scenes: {
        "miou": round(100 * report["mean"]["dataset_level"]["miou"], 2), "rooms": len(scenes)})
    monkeypatch.setattr(trial, "load_checkpoint", lambda path: {"counters": {"cpu_seconds": 9.0}})
    monkeypatch.setattr(trial, "read_meta", lambda path: {"step": 4})
    for arm, seed in MIOU:
        trial.run_trial(spec, arm, seed, tmp_path / "out" / "shift", "sqlite:///x.db")

    for (run, split), (world, scenes, temperature) in seen.items():
        assert temperature == 3.5, "every split is scored at the temperature fitted on the validation rooms"
        if split == "held_out":  # held-out views of the arm's own training rooms
            assert scenes == ["train0"] and world.train_scenes == 2
            assert world.randomise == (1.0 if run.startswith("shift-rand") else 0.0)
        else:  # 16 rooms of the split's own region, the study world's seed, no training room, no randomisation
            assert (world.split, world.test_scenes, world.train_scenes, world.seed, world.randomise) == (
                SPLIT_RESULTS[split], 16, 0, 0, 0.0)
    assert len(seen) == 4 * 5
    stored = read_results(spec.results_dir)
    assert set(stored["rand--s1"]["metrics"]) == set(spec.evaluations)
    assert stored["rand--s1"]["metrics"]["zero_shot_appearance"] == {"miou": 50.0, "rooms": 3}

    text = write_page(spec, tmp_path / "docs").read_text()
    # rand is chosen on validation (61.5 vs 58.5); its appearance gaps 6 and 9 points, geometry gaps 5 and 7
    app, geo = statistics.stdev([6.0, 9.0]), statistics.stdev([5.0, 7.0])
    assert (f"**Headline: arm rand (chosen on the validation rooms) loses appearance-shifted 7.50 ± {app:.2f} (2) "
            f"points and geometry-shifted 6.00 ± {geo:.2f} (2) points from in-distribution**") in text
    rows = {"rand": "**rand** | 60.00 ± 1.41 (2) | 52.50 ± 3.54 (2) | 54.00 ± 2.83 (2) | 7.50 ± 2.12 (2) | "
                    "6.00 ± 1.41 (2)",
            "base": "base | 61.00 ± 1.41 (2) | 39.00 ± 1.41 (2) | 52.50 ± 3.54 (2) | 22.00 ± 2.83 (2) | "
                    "8.50 ± 4.95 (2)"}  # in-distribution, appearance, geometry side by side, then the two gaps
    assert all(f"\n{row}\n" in text for row in rows.values())
    assert "Test splits: 16 rooms each" in text and "the generator's validation stream" in text
