"""``sray lab demo-result``: a finished demo's output folder (made by hand with known numbers,
demo_output_fixtures.py) stored as the demo's run, refused when it is not one demo's folder or its fleet ran with
another budget; the README's ``synth-demo`` card row and the demo's time published from the stored runs, changing
when they change."""

from __future__ import annotations

import json
import shutil
import statistics
from pathlib import Path

import pytest
from demo_output_fixtures import COUNTERS, DEMO_WALL_S, FLEET, FRAMES_PER_S, JOB, ZERO_SHOT, write_demo_output
from train_fixtures import tiny_shards  # noqa: F401

from sray.jobs.cli import main
from sray.lab.publish.figures import CARDS_DATA, demo_time, recipe_cards
from sray.lab.publish.results import RESULTS
from sray.lab.recipe.demo_result import demo_result
from sray.lab.studies.results import read_results, write_result
from sray.platform.common.eval_protocol import EvalProtocol
from sray.platform.common.machine import describe_machine

REPO = Path(__file__).resolve().parents[1]


def test_a_demo_folder_becomes_its_stored_run(tmp_path: Path, tiny_shards: Path) -> None:  # noqa: F811
    """Counters of the job's last checkpoint (not the scored one), the zero-shot scores with their protocol, every
    fleet method's mIoU after its finetune, the render rate and the output files' time span, as written."""
    out = write_demo_output(tmp_path / "demo", tiny_shards, seed=3)
    results = tmp_path / "results" / "demo"
    assert main(["lab", "demo-result", str(out), "--results", str(results)]) == 0
    stored = read_results(results)["make-demo--s3"]
    assert (stored["study"], stored["arm"], stored["seed"], stored["recipe"]) == ("demo", "make-demo", 3, "synth-demo")
    assert stored["trained"] == {"ray_steps": 400, "steps_2d": 200, "cpu_seconds": COUNTERS["cpu_seconds"],
                                 "wall_seconds": COUNTERS["wall_seconds"],
                                 "peak_memory_gib": round(COUNTERS["peak_memory_mb"] / 1024, 3)}
    assert stored["budget"] == {"cpu_seconds": None, "steps": 600}
    zero_shot = stored["metrics"]["zero_shot"]
    assert {k: zero_shot[k] for k in ZERO_SHOT} == {k: round(100 * v, 2) for k, v in ZERO_SHOT.items()}
    metrics = json.loads((out / "eval" / "metrics.json").read_text())
    assert zero_shot["protocol"] == EvalProtocol.from_json(metrics["protocol"]).describe() and zero_shot["rooms"] == 1
    fleet = stored["metrics"]["fleet"]
    assert list(fleet) == list(FLEET)
    for method, (before, after) in FLEET.items():
        assert (fleet[method]["miou"], fleet[method]["miou_before"]) == (round(100 * after, 2), round(100 * before, 2))
        assert fleet[method]["rooms"] == ["synth_test_000"] and fleet[method]["budget"] == "60 s per room"
    assert stored["metrics"]["render"]["seconds_per_frame"] == round(1 / FRAMES_PER_S, 3)
    assert stored["metrics"]["demo"] == {"wall_seconds": DEMO_WALL_S, "wall_rule": "first to last output file",
                                         "train_rooms": 2, "test_rooms": 1}
    assert stored["machine"] == describe_machine() and stored["source"].startswith("run: sray demo --out ")


def test_a_folder_of_two_runs_or_a_fleet_of_another_budget_is_refused(tmp_path: Path, tiny_shards: Path,  # noqa: F811
                                                                      capsys: pytest.CaptureFixture[str]) -> None:
    out = write_demo_output(tmp_path / "demo", tiny_shards, budget_s=30.0)
    args = ["lab", "demo-result", str(out), "--results", str(tmp_path / "results")]
    assert main(args) == 2
    assert "fleet_results.json: synth_test_000/sray trained 30.4 s" in capsys.readouterr().err
    assert main([*args, "--finetune-seconds", "30"]) == 0
    assert main([*args, "--finetune-seconds", "15"]) == 2 and "pass the demo's --finetune-seconds" in \
        capsys.readouterr().err
    (out / "train" / "synth-demo-20261208-080000").mkdir()
    assert main([*args, "--finetune-seconds", "30"]) == 2
    assert f"holds jobs ['synth-demo-20261208-080000'] beside {JOB}" in capsys.readouterr().err


def _repo(tmp_path: Path) -> Path:
    """A repository holding the stored data the recipe cards and the demo's time read."""
    repo = tmp_path / "repo"
    shutil.copytree(REPO / RESULTS, repo / RESULTS)
    (repo / CARDS_DATA).parent.mkdir(parents=True)
    shutil.copy(REPO / CARDS_DATA, repo / CARDS_DATA)
    return repo


def _row(repo: Path) -> str:
    return next(line for line in recipe_cards(repo).splitlines() if line.startswith("synth-demo | 2-core CPU |"))


def test_the_synth_demo_card_is_published_from_the_stored_demo_runs(tmp_path: Path,
                                                                     tiny_shards: Path) -> None:  # noqa: F811
    """One stored run: its values and its seed; a second seed: mean ± sample sd of the two, as a hand computation gives
    them; the demo's time lists both runs."""
    repo, folder = _repo(tmp_path), None
    shipped = _row(repo)
    for seed, scale in ((0, 1.0), (1, 1.1)):
        result = demo_result(write_demo_output(tmp_path / f"demo{seed}", tiny_shards, seed=seed, scale=scale))
        folder = write_result(repo / RESULTS / "demo", result | {"machine": {**result["machine"], "cores": 2,
                                                                             "device": "cpu"}}).parent
        if seed == 0:
            one = _row(repo)
            assert one != shipped
            assert one == ("synth-demo | 2-core CPU | 4.0 min | 5.0 min | 1.2 GiB | 25.0% (seed 0) | not measured | "
                           "not measured | not measured | 83.0% | 0.40 wall s / frame (fly-through)")
    two = _row(repo).split(" | ")

    def pm(values: list[float], digits: int) -> str:
        return f"{statistics.mean(values):.{digits}f} ± {statistics.stdev(values):.{digits}f}"

    assert two[2] == f"{pm([4.0, 4.4], 1)} min" and two[5] == f"{pm([25.0, 27.5], 1)}% (seeds 0-1)"
    assert two[9] == f"{pm([83.0, 91.3], 1)}%" and two[10] == f"{pm([0.4, 0.44], 2)} wall s / frame (fly-through)"
    note = recipe_cards(repo)
    assert f"`semantic-nerf` {pm([17.0, 18.7], 1)}%" in note and "60 s per room on synth_test_000" in note
    walls = [DEMO_WALL_S / 60, 1.1 * DEMO_WALL_S / 60]
    assert f"the demo took {walls[0]:.1f} and {walls[1]:.1f} minutes in 2 runs" in demo_time(repo)
    assert sorted(p.name for p in folder.iterdir()) == ["make-demo--s0.json", "make-demo--s1.json"]


def test_the_hour_card_shows_each_shifted_split_its_shipped_trials_store(tmp_path: Path) -> None:
    """Stored trials that scored the appearance- and geometry-shifted rooms fill those columns (mean ± sample sd over
    the trials holding the split); a split no trial scored says so."""
    repo = _repo(tmp_path)
    cards = recipe_cards(repo).splitlines()
    assert cards[0].split(" | ")[5:8] == ["zero-shot mIoU", "appearance-shifted zero-shot mIoU",
                                          "geometry-shifted zero-shot mIoU"]
    shipped = sorted((repo / RESULTS / "hour-recipe").glob("hour-intra-uncapped--s*.json"))
    for path, appearance in zip(shipped, (41.0, 44.0)):
        trial = json.loads(path.read_text())
        trial["metrics"]["zero_shot_appearance"] = {"miou": appearance}
        path.write_text(json.dumps(trial))
    row = next(line for line in recipe_cards(repo).splitlines() if line.startswith("synth-cpu-hour | 2-core CPU"))
    sd = statistics.stdev([41.0, 44.0])
    assert row.split(" | ")[6:8] == [f"42.5 ± {sd:.1f}%", "not stored"]
