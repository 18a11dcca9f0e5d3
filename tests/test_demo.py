"""The README's main job, ``sray demo``, end to end at toy sizes: every stage leaves its result."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import pytest

from sray.jobs.cli import main


def test_demo_data_only_writes_checked_shards_and_a_sample_picture(tmp_path: Path, monkeypatch) -> None:
    monkeypatch.chdir(tmp_path)
    code = main(["demo", "--out", "demo", "--train-scenes", "1", "--test-scenes", "1", "--views", "20",
                 "--height", "48", "--width", "64", "--steps", "0"])
    assert code == 0
    manifest = json.loads((tmp_path / "demo/shards/manifest.json").read_text())
    assert len(manifest["scenes"]) == 2
    assert (tmp_path / "demo/loader_sample.png").stat().st_size > 10_000
    assert not (tmp_path / "demo/train").exists() and not (tmp_path / "mlflow.db").exists()


@pytest.mark.slow
def test_demo_runs_every_stage_and_tracks_them(ray_session, tmp_path: Path, monkeypatch, capsys) -> None:
    from mlflow import MlflowClient

    monkeypatch.chdir(tmp_path)
    code = main(["demo", "--out", "demo", "--train-scenes", "2", "--test-scenes", "1", "--views", "20",
                 "--height", "48", "--width", "64", "--steps", "4", "--finetune-seconds", "2", "--eval-stride", "4",
                 "--clip-frames", "3"])
    assert code == 0
    out = capsys.readouterr().out
    for stage in range(1, 9):
        assert f"[demo] {stage}/8" in out
    assert "ui   (then open the printed URL)" in out
    [speed] = [ln for ln in out.splitlines() if ln.startswith("[demo] speed vs accuracy")]
    assert "full render" in speed and "fast render" in speed and "points)" in speed
    eval_metrics = json.loads((tmp_path / "demo/eval/metrics.json").read_text())
    assert "synth_test_000" in json.dumps(eval_metrics)
    # --eval-stride 4: the evaluation is strided, so it has no SSIM; the fleet scores every 8th pixel
    assert eval_metrics["protocol"]["stride"] == 4 and eval_metrics["mean"]["colour"]["ssim"] is None
    fleet = tmp_path / "demo/fleet"
    for method in ("sray", "semantic-nerf"):
        result = json.loads((fleet / f"scenes/synth_test_000/{method}/result.json").read_text())
        assert result["status"] == "finished" and result["steps_used"] > 0
        assert result["protocol"]["stride"] == 8
    assert "(stride 4), so no SSIM" in out and "Protocol (semantic-nerf): sources: none (per-scene model)" in out
    [webm] = (tmp_path / "demo/render").rglob("*.webm")
    video = cv2.VideoCapture(str(webm))
    frames = 0
    while video.read()[0]:
        frames += 1
    assert frames == 3, f"{webm}: {frames} frames decoded, the demo asked for 3"
    assert f"render --checkpoint {tmp_path / 'demo/train'}" in out or "render --checkpoint demo/train" in out
    charts = sorted(p.name for p in (fleet / "charts").glob("*.png"))
    assert charts, "the fleet wrote no chart"
    client = MlflowClient(tracking_uri=f"sqlite:///{tmp_path / 'mlflow.db'}")
    names = {e.name for e in client.search_experiments()}
    runs = client.search_runs([e.experiment_id for e in client.search_experiments()])
    assert len(runs) >= 5 and len(names) >= 3  # training, evaluation, the fly-through, fleet parent and its children
    assert "sray-render" in names
