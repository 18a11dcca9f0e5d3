"""The stability suite on given models, without Ray: given checkpoints and segmenter are used and nothing is
pretrained (the data defaulting to the checkpoint's shards), a missing model fails up front naming its flag, one
CPU-second budget stops every trained-on-scene row, and the zero-shot rows built by the registry score as ``sray
eval`` scores them, ``2d-transfer`` and S-Ray given the source depth included."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import pytest
from fleet_fixtures import one_thread, tiny_checkpoint, tiny_segmenter, write_tiny_checkpoint  # noqa: F401
from train_fixtures import tiny_shards  # noqa: F401

from sray.data_tools.loader.shard_loader import make_eval_samples
from sray.jobs.cli import build_parser, main
from sray.jobs.stability import suite_job, world
from sray.jobs.stability.suite_job import StabilityJob, prepare
from sray.platform.checkpoints.model_loading import model_from_checkpoint
from sray.platform.eval.view_scoring import score_scene
from sray.platform.finetune.methods.registry import method_names
from sray.platform.stability.axes import PRESETS, point_spec
from sray.platform.stability.points_study import SuiteInputs, suite_for
from sray.platform.stability.rows import SuiteModels, suite_rows
from sray.platform.stability.suite import compute_spec

pytestmark = pytest.mark.usefixtures("one_thread")
SCENE = "synth_test_000"
BUDGET = 0.2
"""CPU seconds of every trained row in these tests."""


@pytest.fixture(scope="module")
def no_cra_checkpoint(tiny_shards: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A tiny step-0 checkpoint trained with ``model.attention=none``."""
    return write_tiny_checkpoint(tiny_shards, tmp_path_factory.mktemp("no-cra"), seed=1, attention="none")


def _job(tmp_path: Path, *flags: str) -> StabilityJob:
    return StabilityJob.from_args(build_parser().parse_args(["stability", "--preset", "toy", "--out", str(tmp_path),
                                                             "--device", "cpu", *flags]))


def test_given_models_are_used_and_nothing_is_pretrained(tiny_shards, tiny_checkpoint, no_cra_checkpoint,
                                                         tiny_segmenter, tmp_path, monkeypatch) -> None:
    def refuse(*args, **kwargs):
        raise AssertionError("pretrained although the models were given")

    for name in ("world_shards", "world_models"):
        monkeypatch.setattr(suite_job, name, refuse)
    for name in ("pretrain", "pretrain_segmenter", "launch_training", "train_segmenter", "make_world"):
        monkeypatch.setattr(world, name, refuse)
    given = ["--checkpoint", str(tiny_checkpoint), "--checkpoint-no-cra", str(no_cra_checkpoint),
             "--segmenter", str(tiny_segmenter)]
    suite, rows = prepare(_job(tmp_path, *given))
    assert suite.models == SuiteModels(tiny_checkpoint.resolve(), no_cra_checkpoint.resolve(),
                                       tiny_segmenter.resolve())
    trained_on = Path(model_from_checkpoint(tiny_checkpoint)[1].data.shards).resolve()
    assert Path(suite.shards) == trained_on and suite.scenes == (SCENE,)  # the checkpoint's shards, not --data
    assert [r.name for r in rows] == ["sray", "sray-no-cra", "sray-rgbd", "2d-transfer", "sray-scene",
                                      "semantic-nerf-scene", "sray-rgbd-scene", "2d-transfer-scene"]
    with pytest.raises(AssertionError, match="pretrained although"):  # the same job with no model pretrains
        prepare(_job(tmp_path))


def test_a_missing_or_misplaced_model_is_one_clear_line(tiny_shards, tiny_checkpoint, tmp_path, capsys) -> None:
    assert main(["stability", "--preset", "toy", "--checkpoint", str(tiny_checkpoint), "--out", str(tmp_path)]) == 2
    assert "pass --segmenter FOLDER" in capsys.readouterr().err
    assert main(["stability", "--preset", "toy", "--segmenter", str(tmp_path)]) == 2
    assert "need --checkpoint" in capsys.readouterr().err
    assert main(["stability", "--preset", "toy", "--checkpoint", "/no/such"]) == 2
    assert "--checkpoint /no/such: no such folder" in capsys.readouterr().err
    job = _job(tmp_path, "--checkpoint", str(tiny_checkpoint), "--methods", "sray", "semantic-nerf")
    assert [r.name for r in prepare(job)[1]] == ["sray", "sray-scene", "semantic-nerf-scene"]  # no segmenter needed


def _inputs(shards: Path, checkpoint: Path, segmenter: Path, modes: list[str]) -> SuiteInputs:
    _, cfg = model_from_checkpoint(checkpoint)
    preset = dataclasses.replace(PRESETS["toy"], scene_cpu_seconds=BUDGET)
    rows = suite_rows(method_names(), modes, cfg.model, None)
    return SuiteInputs(preset, str(shards), (SCENE,), tuple(rows), SuiteModels(checkpoint, segmenter=segmenter),
                       cfg.model.n_classes, cfg.model.ignore_id, "cpu")


def test_one_cpu_second_budget_stops_every_trained_row(tiny_shards, tiny_checkpoint, tiny_segmenter) -> None:
    inputs = _inputs(tiny_shards, tiny_checkpoint, tiny_segmenter, ["scene"])
    suite = suite_for(inputs)
    assert [r.name for r in inputs.rows] == ["sray-scene", "semantic-nerf-scene", "sray-rgbd-scene",
                                             "2d-transfer-scene"]
    for row in inputs.rows:
        result = compute_spec(suite, point_spec("blur", row, 1, 0, inputs.preset), poison=False)
        assert result["status"] == "ok", (row.name, result["error"])
        (cpu_s,), (steps,) = result["cpu_s"], result["steps"]
        assert steps >= 1 and BUDGET <= cpu_s < BUDGET + cpu_s / steps + 0.1, (row.name, cpu_s, steps)


def test_zero_shot_rows_score_as_sray_eval_with_the_source_depth_where_asked(tiny_shards, tiny_checkpoint,
                                                                              tiny_segmenter) -> None:
    inputs = _inputs(tiny_shards, tiny_checkpoint, tiny_segmenter, ["zero-shot"])
    suite = suite_for(inputs)
    preset, results = inputs.preset, {}
    for row in inputs.rows:
        results[row.name] = compute_spec(suite, point_spec("blur", row, 1, 0, preset), poison=False)
        assert results[row.name]["status"] == "ok", (row.name, results[row.name]["error"])
        model = suite.models[row.name]
        samples = make_eval_samples(tiny_shards, SCENE, n_source=preset.n_source)  # `sray eval`'s sources
        scores = score_scene(model.renderer, samples, model.n_classes, model.ignore_id, preset.eval_stride,
                             preset.chunk, model.device).scores
        assert results[row.name]["miou"] == pytest.approx(100 * scores["miou"], abs=1e-9), row.name
        assert results[row.name]["psnr"] == pytest.approx(scores["psnr"], abs=1e-9), row.name
    assert [r.name for r in inputs.rows] == ["sray", "sray-rgbd", "2d-transfer"]
    assert suite.models["sray-rgbd"].inputs == "rgbd" and suite.models["sray"].inputs == "rgb"
    assert results["sray-rgbd"]["psnr"] != results["sray"]["psnr"]  # the depth placed other samples
