"""The README's main job, ``sray demo``, end to end at toy sizes: every stage leaves its result."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pytest

from sray.jobs.cli import main
from sray.jobs.demo import train_segmenter_stage
from sray.platform.checkpoints.folders import CheckpointManager, load_checkpoint
from sray.platform.finetune.methods.registry import get_method


def test_demo_data_only_writes_checked_shards_and_a_sample_picture(tmp_path: Path, monkeypatch) -> None:
    monkeypatch.chdir(tmp_path)
    code = main(["demo", "--out", "demo", "--train-scenes", "1", "--test-scenes", "1", "--views", "20",
                 "--height", "48", "--width", "64", "--steps", "0"])
    assert code == 0
    manifest = json.loads((tmp_path / "demo/shards/manifest.json").read_text())
    assert len(manifest["scenes"]) == 2
    assert (tmp_path / "demo/loader_sample.png").stat().st_size > 10_000
    assert not (tmp_path / "demo/train").exists() and not (tmp_path / "mlflow.db").exists()
    assert not (tmp_path / "demo/segmenter").exists()


@pytest.mark.slow
def test_demo_runs_every_stage_and_tracks_them(ray_session, tmp_path: Path, monkeypatch, capsys) -> None:
    from mlflow import MlflowClient

    monkeypatch.chdir(tmp_path)
    code = main(["demo", "--out", "demo", "--train-scenes", "2", "--test-scenes", "2", "--views", "20",
                 "--height", "48", "--width", "64", "--steps", "4", "--finetune-seconds", "2", "--eval-stride", "4",
                 "--clip-frames", "3", "--segmenter-cpu-seconds", "1"])
    assert code == 0
    out = capsys.readouterr().out
    for stage in range(1, 10):
        assert f"[demo] {stage}/9" in out
    assert "ui   (then open the printed URL)" in out
    [speed] = [ln for ln in out.splitlines() if ln.startswith("[demo] speed vs accuracy")]
    assert "full render" in speed and "fast render" in speed and "points)" in speed
    eval_metrics = json.loads((tmp_path / "demo/eval/metrics.json").read_text())
    assert "synth_test_000" in json.dumps(eval_metrics) and "synth_test_001" in json.dumps(eval_metrics)
    # --eval-stride 4: the evaluation is strided, so it has no SSIM; the fleet scores every 8th pixel
    assert eval_metrics["protocol"]["stride"] == 4 and eval_metrics["mean"]["colour"]["ssim"] is None
    # stage 6: the segmenter trained on the train scenes for S-Ray's CPU seconds, capped here at 1 CPU s
    state = load_checkpoint(CheckpointManager(next((tmp_path / "demo/train").iterdir()) / "checkpoints").latest())
    sray_cpu_s = state["counters"]["cpu_seconds"]
    # the demo's recipe with 4 of its 600 steps keeps its 2D-only warm-up at a third: round(4 * 200 / 600) = 1 step
    assert state["config"]["recipe"] == "synth-demo" and state["config"]["optim"]["warmup_2d_steps"] == 1
    # and the recipe's data order, the loader's default: a loader epoch per checkpoint interval (here 2 steps)
    assert state["config"]["data"]["epoch_steps"] == 0 and state["config"]["run"]["ckpt_every"] == 2
    assert "first 1 on the source views' labels alone" in out
    assert sray_cpu_s > 1.0  # so the cap is what set the budget
    training = json.loads((tmp_path / "demo/segmenter/segmenter.json").read_text())["training"]
    assert training["cpu_seconds_budget"] == 1.0 and training["steps"] >= 1
    assert 1.0 <= training["cpu_seconds"] < 1.0 + 5.0  # the loop stops at the first step past the budget
    assert training["scenes"] == ["synth_train_000", "synth_train_001"] and training["n_source"] == 4
    assert f"capped by --segmenter-cpu-seconds below the {sray_cpu_s:.0f} CPU s S-Ray's training spent" in out
    assert f"S-Ray 4 steps, {sray_cpu_s:.0f} CPU s; 2d-transfer's segmenter {training['cpu_seconds']:.0f} CPU s" in out
    fleet = tmp_path / "demo/fleet"
    for method, inputs in (("sray", "rgb"), ("semantic-nerf", "rgb"), ("sray-rgbd", "rgbd"), ("2d-transfer", "rgbd")):
        result = json.loads((fleet / f"scenes/synth_test_000/{method}/result.json").read_text())
        assert result["status"] == "finished" and result["steps_used"] > 0
        assert result["protocol"]["stride"] == 8 and result["protocol"]["inputs"] == inputs
        assert f"| synth_test_000 | {method} | {'RGB-D' if inputs == 'rgbd' else 'RGB'} | finished |" in out
    assert "also running sray-rgbd" in out  # the demo asks for 2d-transfer; the fleet adds S-Ray given the depth
    assert not (fleet / "scenes/synth_test_001").exists()  # the fleet finetunes --fleet-scenes (default 1) of them
    assert "8/9 finetune fleet on 1 of the 2 unseen scenes (synth_test_000)" in out
    assert "(stride 4), so no SSIM" in out and "Protocol (semantic-nerf): sources: none (per-scene model)" in out
    assert "Protocol (2d-transfer): sources: 4 per query" in out
    [webm] = (tmp_path / "demo/render").rglob("*.webm")
    video = cv2.VideoCapture(str(webm))
    frames = 0
    while video.read()[0]:
        frames += 1
    assert frames == 3, f"{webm}: {frames} frames decoded, the demo asked for 3"
    assert f"render --checkpoint {tmp_path / 'demo/train'}" in out or "render --checkpoint demo/train" in out
    charts = sorted(p.name for p in (fleet / "charts").glob("*.png"))
    assert charts, "the fleet wrote no chart"
    chart = cv2.cvtColor(cv2.imread(str(fleet / "charts/miou_vs_step.png")), cv2.COLOR_BGR2RGB).astype(int)
    transfer_colour = np.array([int(get_method("2d-transfer").style.color[i:i + 2], 16) for i in (1, 3, 5)])
    assert (np.abs(chart - transfer_colour).max(-1) <= 12).sum() > 20, "no 2d-transfer curve in the chart"
    client = MlflowClient(tracking_uri=f"sqlite:///{tmp_path / 'mlflow.db'}")
    names = {e.name for e in client.search_experiments()}
    runs = client.search_runs([e.experiment_id for e in client.search_experiments()])
    assert len(runs) >= 6 and len(names) >= 3  # training, evaluation, the fly-through, fleet parent and its children
    assert "sray-render" in names
    assert {"synth_test_000 · sray", "synth_test_000 · 2d-transfer"} <= {r.info.run_name for r in runs}

    # uncapped (0), the segmenter gets exactly what S-Ray's training spent
    record, note = train_segmenter_stage(tmp_path / "demo/shards", tmp_path / "equal", 0.0, 0.5, 0)
    assert record.training["cpu_seconds_budget"] == 0.5 and "(equal CPU)" in note
    assert (tmp_path / "equal/segmenter.pt").exists()
