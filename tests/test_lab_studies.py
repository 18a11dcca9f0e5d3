"""Studies as files (``sray lab study``): the spec's checks, paired differences against a hand computation, the page
regenerated with its Reading kept, and a resumed study running only its missing trials (the engine's Tune run
replaced by its trial wrapper in this process, as in test_sweep_spec.py; the trial function mocked)."""

from __future__ import annotations

import json
import statistics
from pathlib import Path

import pytest
from engine_here import run_study_here

from sray.jobs.cli import main
from sray.lab.studies import runner, trial
from sray.lab.studies.page import MAX_READING_LINES, READING, write_page
from sray.lab.studies.paired import paired_differences
from sray.lab.studies.results import FORMAT, read_results, write_result
from sray.lab.studies.spec import StudyError, load_study
from sray.platform.sweep import engine
from sray.platform.sweep.study import TrialContext

REPO = Path(__file__).resolve().parents[1]

SPEC = """study: toy
description: Does a larger learning rate help the toy recipe?
recipe: synth-small
world: {train_scenes: 2, test_scenes: 1, views: 20, height: 24, width: 32}
validation: {seed: 5, rooms: 1}
set: {run.workers: 1}
baseline: base
arms:
  base: {}
  lr-2x: {optim.lr: 0.002, optim.lr_final: 0.0002}
  ema: {set: {optim.ema_decay: 0.998}, budget: {steps: 8}, removed_after: 7734061, note: lost at equal CPU}
seeds: [0, 1]
budget: {cpu_seconds: 30}
evaluations: [zero_shot, held_out, validation]
"""


def _spec(tmp_path: Path, text: str = SPEC) -> Path:
    path = tmp_path / "studies" / "toy.yaml"
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text)
    return path


def _result(arm: str, seed: int, miou: dict[str, float], source: str = "run") -> dict:
    return {"format": FORMAT, "study": "toy", "arm": arm, "seed": seed, "recipe": "synth-small", "overrides": {},
            "budget": {"cpu_seconds": 30.0, "steps": None},
            "trained": {"ray_steps": 10 + seed, "cpu_seconds": 29.5, "wall_seconds": 20.0, "peak_memory_gib": 0.5},
            "metrics": {split: {"miou": value} for split, value in miou.items()},
            "machine": {"cpu_model": "toy CPU", "cores": 2, "device": "cpu", "ray_steps_per_cpu_second": None},
            "commit": "abc1234", "source": source}


def test_a_study_file_parses_into_arms_seeds_budgets_and_a_separate_validation_world(tmp_path: Path) -> None:
    spec = load_study(_spec(tmp_path))
    assert list(spec.arms) == ["base", "lr-2x", "ema"] and spec.baseline == "base" and spec.seeds == (0, 1)
    assert spec.arms["lr-2x"].overrides() == ["optim.lr=0.002", "optim.lr_final=0.0002"]
    assert spec.arms["ema"].budget.steps == 8 and spec.arms["ema"].removed_after == "7734061"
    assert spec.budget.cpu_seconds == 30.0 and spec.select_on == "validation"
    val = spec.validation_world()
    assert (val.seed, val.train_scenes, val.test_scenes, val.views) == (5, 0, 1, 20) and spec.world.seed == 0
    assert list(spec.trial_keys())[:3] == ["base--s0", "base--s1", "lr-2x--s0"] and len(spec.trial_keys()) == 6
    assert spec.results_dir == tmp_path / "studies" / "results" / "toy"
    with pytest.raises(ValueError, match="ema_decay"):  # its field left the product: its results stay, it cannot rerun
        trial.trial_config(spec, spec.arms["ema"], 1, tmp_path / "shards", tmp_path, "sqlite:///x.db")
    cfg = trial.trial_config(spec, spec.arms["lr-2x"], 1, tmp_path / "shards", tmp_path, "sqlite:///x.db")
    assert (cfg.optim.lr, cfg.optim.cpu_seconds, cfg.run.seed) == (0.002, 30.0, 1)
    assert cfg.run.workers == 1 and cfg.run.name == "toy-lr-2x-s1"


@pytest.mark.parametrize("change, field, fix", [
    (("study: toy", "study: other"), "study", "write study: toy"),
    (("recipe: synth-small", "recipe: synth-huge"), "recipe", "use one of"),
    (("validation: {seed: 5, rooms: 1}\n", ""), "validation", "a study names study, recipe, world, validation"),
    (("validation: {seed: 5, rooms: 1}", "validation: {seed: 5}"), "validation",
     "give validation: {seed: 1, rooms: 4}"),
    (("validation: {seed: 5,", "validation: {seed: 0,"), "validation.seed", "choose another seed"),
    (("seeds: [0, 1]", "seeds: [0, 0]"), "seeds", "seeds: [0, 1, 2]"),
    (("budget: {cpu_seconds: 30}", "budget: {minutes: 3}"), "budget", "give cpu_seconds"),
    (("{optim.lr: 0.002,", "{lr: 0.002,"), "arms.lr-2x", "section.field"),
    (("removed_after: 7734061", "removed_after: yesterday"), "arms.ema.removed_after", "write its hash"),
    (("baseline: base", "baseline: best"), "baseline", "name one of base, lr-2x, ema"),
    (("evaluations: [zero_shot, held_out, validation]", "evaluations: [zero_shot, validation]\n"
      "select_on: zero_shot"), "select_on", "never on the test rooms"),
    (("world: {train_scenes: 2,", "world: {rooms: 2,"), "world.rooms", "not a world field"),
])
def test_a_wrong_study_file_is_one_error_naming_the_file_the_field_and_the_fix(tmp_path: Path, change: tuple,
                                                                               field: str, fix: str) -> None:
    path = _spec(tmp_path, SPEC.replace(*change))
    with pytest.raises(StudyError) as caught:
        load_study(path)
    message = str(caught.value)
    assert message.startswith(f"{path}: {field}:") and fix in message and "\n" not in message


def test_paired_differences_match_a_hand_computation(tmp_path: Path) -> None:
    """Per shared seed arm minus baseline; mean and sample std over those seeds only."""
    results = {f"{a}--s{s}": _result(a, s, {"zero_shot": v}) for a, s, v in
               [("base", 0, 50.0), ("base", 1, 52.0), ("base", 2, 47.0), ("lr-2x", 0, 53.5), ("lr-2x", 1, 51.0),
                ("lr-2x", 3, 70.0), ("ema", 2, 46.0)]}
    by_arm = {p.arm: p for p in paired_differences(results, "base", "zero_shot")}
    assert by_arm["lr-2x"].seeds == (0, 1) and by_arm["lr-2x"].differences == (3.5, -1.0)
    assert by_arm["lr-2x"].mean == pytest.approx(1.25)
    assert by_arm["lr-2x"].std == pytest.approx(statistics.stdev([3.5, -1.0])) == pytest.approx(3.1819805)
    assert by_arm["ema"].differences == (-1.0,) and by_arm["ema"].std is None
    assert paired_differences(results, "base", "validation")[0].seeds == ()


def test_the_page_is_regenerated_from_the_results_and_keeps_its_reading(tmp_path: Path) -> None:
    spec = load_study(_spec(tmp_path))
    for arm, seed, zs, val in [("base", 0, 50.0, 40.0), ("base", 1, 52.0, 44.0), ("lr-2x", 0, 53.5, 41.0),
                               ("lr-2x", 1, 51.0, 46.5)]:
        write_result(spec.results_dir, _result(arm, seed, {"zero_shot": zs, "validation": val}))
    docs = tmp_path / "docs"
    page = write_page(spec, docs)
    text = page.read_text()
    assert "**Selection split: validation.**" in text and "room(s) of world seed 5" in text
    assert "**base** | the base recipe | 51.00 ± 1.41 (2) | 42.00 ± 2.83 (2)\n" in text
    assert "lr-2x | validation rooms | 0, 1 | +1.00, +2.50 | +1.75 ± 1.06\n" in text
    assert "ema | `optim.ema_decay=0.998` | removed from the product after 7734061 | lost at equal CPU\n" in text
    assert (docs / "studies" / "toy" / "miou.png").stat().st_size > 1000
    reading = ["The larger learning rate wins on validation by 1.75 ± 1.06 points.", "", "Second paragraph."]
    page.write_text(text + "\n".join(reading) + "\n")
    write_result(spec.results_dir, _result("ema", 0, {"zero_shot": 45.0, "validation": 39.0}))
    again = write_page(spec, docs).read_text()
    assert again.endswith("\n".join(reading) + "\n") and again.count(READING) == 1
    assert "\nema | 0 | 45.00 | 39.00 | 10 | 30 | toy CPU | 2 | run\n" in again and "5 of 6 trials stored" in again
    page.write_text(again + "\n".join(f"line {i}" for i in range(MAX_READING_LINES)) + "\n")
    with pytest.raises(ValueError, match=f"{page}: its Reading has 18 lines; shorten it to at most 15"):
        write_page(spec, docs)
    assert page.read_text().endswith(f"line {MAX_READING_LINES - 1}\n"), "a refused page is left as it was"


def test_a_resumed_study_runs_only_its_missing_trials(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                      capsys: pytest.CaptureFixture[str]) -> None:
    spec_path = _spec(tmp_path, SPEC.replace("seeds: [0, 1]", "seeds: [0]"))
    spec = load_study(spec_path)
    ran: list[tuple[str, int]] = []
    kill = ["ema"]

    def fake_trial(spec, arm: str, seed: int, out: Path, tracking_uri: str) -> dict:
        ran.append((arm, seed))
        if arm in kill:  # its first launch dies
            kill.remove(arm)
            raise RuntimeError("killed")
        result = _result(arm, seed, {"zero_shot": 50.0 + len(arm), "validation": 40.0})
        write_result(spec.results_dir, result)
        return result

    monkeypatch.setattr(trial, "run_trial", fake_trial)
    monkeypatch.setattr(engine, "run_study", run_study_here)
    monkeypatch.setattr(runner, "init_ray", lambda address: None)
    monkeypatch.setattr(TrialContext, "report", lambda self, metrics: None)
    imported = _result("base", 0, {"zero_shot": 48.0}, source="imported: docs/x/tables.json@7734061")
    write_result(spec.results_dir, imported)
    args = ["lab", "study", str(spec_path), "--out", str(tmp_path / "out")]
    assert main([*args, "--dry-run"]) == 0 and "2 of 3 trials to run: lr-2x--s0, ema--s0" in capsys.readouterr().out
    assert main(args) == 1 and ran == [("lr-2x", 0), ("ema", 0)]  # ema's first launch dies
    assert sorted(read_results(spec.results_dir)) == ["base--s0", "lr-2x--s0"]
    assert main(args) == 0 and ran[2:] == [("ema", 0)], "only the trial without a result runs again"
    assert read_results(spec.results_dir)["base--s0"] == imported, "an imported result is never recomputed"
    (spec.results_dir / "lr-2x--s0.json").unlink()
    assert main(args) == 0 and ran[3:] == [("lr-2x", 0)], "deleting a result file runs its trial again"
    assert main(args) == 0 and len(ran) == 4
    assert json.loads((spec.results_dir / "ema--s0.json").read_text())["metrics"]["zero_shot"]["miou"] == 53.0


def test_the_hour_recipe_study_names_the_recipe_and_its_default_world(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                                     capsys: pytest.CaptureFixture[str]) -> None:
    """``synth-cpu-hour``'s default shards are the world ``sray lab study --worlds`` makes for its study's recipe arm;
    ``--worlds`` asks for each distinct world once (the arms' and the validation rooms') and trains nothing."""
    from sray.platform.config.recipes import CPU_HOUR_SHARDS

    spec = load_study(REPO / "jobs" / "studies" / "hour-recipe.yaml")
    recipe = spec.arms["hour-intra-uncapped"]
    assert recipe.sets == {} and spec.recipe == "synth-cpu-hour" and spec.budget.cpu_seconds == 7200
    assert trial.world_folder(Path("outputs/studies"), spec.arm_world(recipe)) / "shards" == Path(CPU_HOUR_SHARDS)
    asked: list = []
    monkeypatch.setattr(runner, "make_world", lambda world, root, progress: asked.append(world) or root / "shards")
    assert main(["lab", "study", "--worlds", str(spec.path), "--out", str(tmp_path)]) == 0
    assert [w.train_scenes for w in asked] == [498, 198, 48, 0] and asked[-1].seed == 1
    assert str(tmp_path / "worlds" / "train498-test4-v40-120x160-s0" / "shards") in capsys.readouterr().out


@pytest.mark.parametrize("spec", sorted((REPO / "jobs" / "studies").glob("*.yaml")), ids=lambda p: p.stem)
def test_every_study_file_parses_and_its_stored_results_belong_to_it(spec: Path) -> None:
    """The shipped study files are valid and each stored result is a trial the file names, with a known source (a
    study not run yet, such as appearance-levers, has none; its page says 0 of N trials stored)."""
    study = load_study(spec)
    results = read_results(study.results_dir)
    assert set(results) <= set(study.trial_keys())
    assert all(r["study"] == study.name and r["source"].startswith(("run", "imported: ", "transcribed: "))
               for r in results.values())
