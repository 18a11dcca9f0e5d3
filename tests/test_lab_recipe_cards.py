"""``sray lab recipe-cards`` on tiny hand-written results: what is read is what is printed, a recipe never run on a
machine says so, a field a result lacks is named in a note, a bad result file is an error naming file and field,
and the README changes only between its markers."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from sray.lab.recipe.cards import README_END, README_START, run_recipe_cards
from sray.platform.checkpoints.folders import CheckpointManager
from sray.platform.config.recipes import RECIPES

COUNTERS = {"skipped_steps": 0, "cpu_seconds": 6600.0, "wall_seconds": 3300.0, "peak_memory_mb": 1536.0}
README = f"# sray\n\nIntro | with a pipe.\n\n{README_START}\nold cards\n{README_END}\n\n## Layout\n\nkept as it is\n"


def _json(path: Path, data: object) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(data))
    return path


def _scene(fleet: Path, scene: str, curve: list[tuple[float, float]], **result: object) -> None:
    _json(fleet / "scenes" / scene / "sray" / "result.json",
          {"scene": scene, "method": "sray", "status": "finished", "steps_used": 300, "max_steps": 300,
           "stopped_early": False, "curve": [{"step": i, "wall_s": w, "miou": m} for i, (w, m) in enumerate(curve)]}
          | result)


def _results(root: Path, counters: dict = COUNTERS, zero_shot: object = 0.264) -> Path:
    """One synth-cpu-hour run on '2-core CPU' with every result, an H100 listed with nothing run on it."""
    CheckpointManager(root / "train" / "job" / "checkpoints").save({"step": 2500, "counters": counters}, 2500)
    _json(root / "eval" / "metrics.json", {"mean": {"dataset_level": {"miou": zero_shot}}})
    _json(root / "heldout" / "metrics.json", {"mean": {"dataset_level": {"miou": 0.48}}})
    _scene(root / "fleet", "a", [(0.0, 0.2), (30.0, 0.4), (59.0, 0.45), (90.0, 0.6)])
    _scene(root / "fleet", "b", [(0.0, 0.1), (40.0, 0.35), (80.0, 0.3)])
    _scene(root / "fleet", "c", [], status="failed")  # failed pairs are not averaged
    _json(root / "speed" / "tables.json", {"tables": [{
        "title": "Default settings", "command": "sray bench speed-accuracy --checkpoint C", "blocks": [
            {"header": ["setting", "mIoU %", "CPU s / view"], "rows": [["full", "22.4", "154.81"],
                                                                       ["fast s8 c0.9", "22.5", "1.69"]]}]}]})
    return _json(root / "cards.json", {"machines": ["H100"], "runs": [
        {"recipe": "synth-cpu-hour", "machine": "2-core CPU", "train": "train/job", "zero_shot": "eval/metrics.json",
         "held_out": "heldout/metrics.json", "finetune": "fleet", "speed": "speed/tables.json"}]})


def _run(tmp_path: Path, listing: Path) -> dict[tuple[str, str], list[str]]:
    """Run the command on a README and a doc in ``tmp_path``; the README's table rows by (recipe, machine)."""
    readme = tmp_path / "README.md"
    if not readme.exists():
        readme.write_text(README)
    run_recipe_cards(listing, readme, tmp_path / "docs" / "benchmarks.md")
    block = readme.read_text().split(README_START)[1].split(README_END)[0]
    lines = [ln.split(" | ") for ln in block.strip().splitlines() if " | " in ln]
    assert lines[0][:3] == ["recipe", "machine", "pretraining wall"] and set(lines[1]) == {"---"}
    return {(cells[0], cells[1]): cells[2:] for cells in lines[2:]}


def test_the_cards_print_what_the_results_hold_and_say_where_a_recipe_never_ran(tmp_path: Path) -> None:
    rows = _run(tmp_path, _results(tmp_path / "results"))
    assert rows[("synth-cpu-hour", "2-core CPU")] == ["55.0 min", "110.0 min", "1.5 GiB", "26.4%", "48.0%",
                                                      "40.0%", "1.69"]  # finetune: (0.45 + 0.35) / 2 within 60 s
    assert set(rows) == {(r, m) for r in RECIPES for m in ("H100", "2-core CPU")}
    assert rows[("synth-paper", "H100")] == ["not run on H100"] + ["—"] * 6
    assert rows[("synth-small", "2-core CPU")][0] == "not run on 2-core CPU"
    section = (tmp_path / "docs" / "benchmarks.md").read_text()
    assert "## Recipe cards (all machines)" in section and "`sray bench speed-accuracy --checkpoint C`" in section
    stored = json.loads((tmp_path / "docs/benchmarks/recipe-cards/all-machines/tables.json").read_text())
    assert {(r[0], r[1]): r[2:] for r in stored["tables"][0]["blocks"][0]["rows"]} == rows  # README = doc's data


def test_the_readme_changes_only_between_its_markers(tmp_path: Path) -> None:
    listing = _results(tmp_path / "results")
    _run(tmp_path, listing)
    first = (tmp_path / "README.md").read_text()
    head, tail = README.split(README_START)[0], README.split(README_END)[1]
    assert first.startswith(head + README_START + "\n") and first.endswith(README_END + tail)
    assert "old cards" not in first
    _json(tmp_path / "results" / "eval" / "metrics.json", {"mean": {"dataset_level": {"miou": 0.3}}})
    rows = _run(tmp_path, listing)  # a second run replaces its own block
    second = (tmp_path / "README.md").read_text()
    assert rows[("synth-cpu-hour", "2-core CPU")][3] == "30.0%" and second.count(README_START) == 1
    assert second.startswith(head + README_START + "\n") and second.endswith(README_END + tail)


def test_a_field_a_result_lacks_is_named_in_a_note_and_a_result_not_given_is_not_measured(tmp_path: Path) -> None:
    listing = _results(tmp_path / "results", counters={"cpu_seconds": 60.0}, zero_shot=None)
    data = json.loads(listing.read_text())
    del data["runs"][0]["finetune"]
    listing.write_text(json.dumps(data))
    rows = _run(tmp_path, listing)
    assert rows[("synth-cpu-hour", "2-core CPU")][:6] == ["missing (1)", "60 s", "missing (2)", "missing (3)", "48.0%",
                                                          "not measured"]
    readme = (tmp_path / "README.md").read_text()
    state = "results/train/job/checkpoints/step_000002500/state.pt"
    assert f"(1) {state} lacks counters.wall_seconds" in readme
    assert f"(2) {state} lacks counters.peak_memory_mb" in readme
    assert "(3) results/eval/metrics.json holds null for mean.dataset_level.miou" in readme


def test_a_chosen_settings_run_gives_the_render_time_only_when_it_measured_the_default_render(tmp_path: Path) -> None:
    """A speed-accuracy run on a chosen set of settings: its row of `sray eval`'s default render is read, with the
    run's command; a chosen set without that row leaves the figure missing, with the file named."""
    listing = _results(tmp_path / "results")
    speed = tmp_path / "results" / "speed" / "tables.json"
    chosen = {"title": "Chosen settings", "command": "sray bench speed-accuracy --settings full 'fast s8 c0.9'",
              "blocks": [{"header": ["setting", "CPU s / view"], "rows": [["full", "40.2"], ["fast s8 c0.9", "0.71"]]}]}
    _json(speed, {"tables": [chosen]})
    assert _run(tmp_path, listing)[("synth-cpu-hour", "2-core CPU")][6] == "0.71"
    assert "`sray bench speed-accuracy --settings full 'fast s8 c0.9'`" in (tmp_path / "README.md").read_text()
    chosen["blocks"][0]["rows"] = [["full", "40.2"], ["fast s4 c0.9", "2.9"]]
    _json(speed, {"tables": [chosen]})
    assert _run(tmp_path, listing)[("synth-cpu-hour", "2-core CPU")][6] == "missing (1)"
    assert ("(1) results/speed/tables.json lacks tables[title='Default settings'] (or a 'Chosen settings' table "
            "with row 'fast s8 c0.9')") in (tmp_path / "README.md").read_text()


def test_results_outside_the_repository_keep_their_path_below_the_listing(tmp_path: Path) -> None:
    """Results stored outside the README's repository are named as OUT/ plus their path below the folder they
    share with the listing, even when one file alone is named (not OUT/<file name>)."""
    listing = _results(tmp_path / "out", counters={"cpu_seconds": 60.0})
    (tmp_path / "repo").mkdir()
    (tmp_path / "repo" / "README.md").write_text(README)
    run_recipe_cards(listing, tmp_path / "repo" / "README.md", tmp_path / "repo" / "docs" / "benchmarks.md")
    text = (tmp_path / "repo" / "README.md").read_text()
    assert "(1) OUT/train/job/checkpoints/step_000002500/state.pt lacks counters.wall_seconds" in text


@pytest.mark.parametrize(("damage", "message"), [
    (lambda root: (root / "eval" / "metrics.json").write_text('{"mean": {"dataset_level": {"miou": "high"}}}'),
     r"results/eval/metrics.json: mean\.dataset_level\.miou is 'high'; expected a finite number"),
    (lambda root: (root / "heldout" / "metrics.json").write_text("{not json"),
     r"results/heldout/metrics.json: not readable as JSON"),
    (lambda root: _scene(root / "fleet", "a", [(0.0, 0.2), (30.0, 0.4)], steps_used=40),
     r"results/fleet/scenes/a/sray/result.json: curve: training stopped at 30 s, before the card's 60 s"),
    (lambda root: _json(root / "speed" / "tables.json", {"tables": [{"title": "Default settings", "blocks": [
        {"header": ["setting", "CPU s / view"], "rows": [["fast s8 c0.9", "fast"]]}]}]}),
     r"results/speed/tables.json: 'Default settings', row 'fast s8 c0.9', column 'CPU s / view'"),
])
def test_a_bad_result_file_is_an_error_naming_the_file_and_the_field(tmp_path: Path, damage, message: str) -> None:
    listing = _results(tmp_path / "results")
    damage(tmp_path / "results")
    (tmp_path / "README.md").write_text(README)
    with pytest.raises(ValueError, match=message):
        _run(tmp_path, listing)
    assert (tmp_path / "README.md").read_text() == README and not (tmp_path / "docs").exists()


@pytest.mark.parametrize(("run", "message"), [
    ({"recipe": "synth-week", "machine": "m"}, r"runs\[0\]: recipe 'synth-week' is not one of"),
    ({"recipe": "synth-small", "machine": "m", "eval": "x"}, r"runs\[0\]: unknown keys \['eval'\]; known:"),
    ({"recipe": "synth-small"}, r"runs\[0\]: give an object with at least \"recipe\" and \"machine\""),
    ({"recipe": "synth-small", "machine": "m", "train": 3}, r"runs\[0\]: train must be a path"),
])
def test_a_bad_list_is_refused_with_the_entry(tmp_path: Path, run: dict, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        _run(tmp_path, _json(tmp_path / "cards.json", {"runs": [run]}))


def test_a_readme_without_the_markers_is_refused_and_left_alone(tmp_path: Path) -> None:
    (tmp_path / "README.md").write_text("# sray\n")
    with pytest.raises(ValueError, match=f"README.md: needs the lines {README_START} and {README_END}"):
        _run(tmp_path, _results(tmp_path / "results"))
    assert (tmp_path / "README.md").read_text() == "# sray\n" and not (tmp_path / "docs").exists()


def test_the_command_line_writes_the_cards_and_exits_2_naming_a_bad_file(tmp_path: Path, capsys) -> None:
    from sray.jobs.cli import main

    listing, readme, doc = _results(tmp_path / "results"), tmp_path / "README.md", tmp_path / "docs" / "benchmarks.md"
    readme.write_text(README)
    args = ["lab", "recipe-cards", "--results", str(listing), "--readme", str(readme), "--doc", str(doc)]
    assert main(args) == 0 and "| 26.4% |" in readme.read_text()
    (tmp_path / "results" / "eval" / "metrics.json").write_text("[]")
    assert main(args) == 2
    assert "results/eval/metrics.json: mean.dataset_level.miou: expected an object" in capsys.readouterr().err
