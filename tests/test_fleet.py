"""The finetune fleet end to end on local Ray: retries, failure reports, MLflow parent/child runs, re-launch."""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import pytest
import torch
from fleet_fixtures import kept_point, tiny_checkpoint, tiny_fleet_config, write_tiny_checkpoint  # noqa: F401
from injected_faults import injected_faults
from mlflow_fixtures import mlflow_template, mlflow_uri  # noqa: F401
from train_fixtures import tiny_shards  # noqa: F401

from sray.data_tools.shards.manifest import unseen_scenes
from sray.platform.checkpoints.folders import load_checkpoint, resolve_checkpoint
from sray.platform.finetune.fleet import run_fleet

CONTRACT_KEYS = {"scene", "method", "status", "error", "attempts", "steps_used", "max_steps", "stopped_early",
                 "stop_reason", "wall_s", "cpu_s", "miou_before", "miou_after", "psnr_after", "artifact_bytes",
                 "full_checkpoint_bytes", "child_run_id", "protocol", "curve", "node_id", "gpu_peak_bytes"}
"""docs/CONTRACTS.md, "Fleet results"."""
CURVE_KEYS = {"step", "wall_s", "miou", "miou_per_image", "psnr"}
SCENES = ["synth_train_000", "synth_train_001", "synth_test_000"]
FAILING = "synth_train_001"


def _client(uri: str):
    from mlflow import MlflowClient

    return MlflowClient(tracking_uri=uri)


def _children(uri: str, parent_id: str) -> list:
    client = _client(uri)
    parent = client.get_run(parent_id)
    return client.search_runs([parent.info.experiment_id], f"tags.mlflow.parentRunId = '{parent_id}'")


def _on_disk(out: Path, scene: str, method: str) -> dict:
    return json.loads((out / "scenes" / scene / method / "result.json").read_text())


SRAY_HELD_OUT_RENDER = "fast (pixel stride 1, fine pass where the coarse confidence < 0.9, resampled depths only)"
"""S-Ray's default held-out render (``finetune.held_out``); Semantic-NeRF renders in full."""


def _protocol(source_rule: str, n_source: int, stride: int, render: str = "full") -> dict:
    """The descriptor a result must carry (docs/CONTRACTS.md, "Protocol descriptor")."""
    return {"source_rule": source_rule, "n_source": n_source, "stride": stride, "render": render, "inputs": "rgb",
            "train_inputs": "rgb", "miou": "dataset-level, classes present in ground truth",
            "miou_per_image": "per-image mean"}


def test_fleet_retries_reports_failure_and_relaunch_skips_finished(ray_session, tiny_shards, tiny_checkpoint,
                                                                   mlflow_uri, tmp_path):
    out = tmp_path / "fleet"
    cfg = tiny_fleet_config()
    with injected_faults(f"fleet.fail_scenes={FAILING}"):
        results = run_fleet(cfg, tiny_checkpoint, tiny_shards, SCENES, out, mlflow_uri, ["sray"])

    assert [r["scene"] for r in results] == SCENES
    model_bytes = sum(t.numel() * t.element_size() for t in load_checkpoint(tiny_checkpoint)["model"].values())
    for r in results:
        assert set(r) == CONTRACT_KEYS
        assert _on_disk(out, r["scene"], "sray") == json.loads(json.dumps(r))
    by_scene = {r["scene"]: r for r in results}
    failed = by_scene[FAILING]
    assert failed["status"] == "failed" and failed["attempts"] == 2  # first try + retries=1
    assert failed["protocol"] is None  # nothing was measured
    rule = json.loads((tiny_shards / "manifest.json").read_text())["neighbours"]
    source_rule = f"{rule['rule']} v{rule['version']}"
    assert "InjectedFailure" in failed["error"]
    for scene in ("synth_train_000", "synth_test_000"):
        r = by_scene[scene]
        assert r["status"] == "finished" and r["attempts"] == 1 and r["error"] is None
        assert r["protocol"] == _protocol(source_rule, cfg.finetune.held_out.n_source, cfg.finetune.held_out.stride,
                                          SRAY_HELD_OUT_RENDER)
        assert r["steps_used"] == 6 and [p["step"] for p in r["curve"]] == [0, 3, 6]
        assert all(set(p) == CURVE_KEYS for p in r["curve"])
        assert r["miou_before"] == r["curve"][0]["miou"]
        assert r["miou_after"] == kept_point(r["curve"], cfg.finetune.min_delta)["miou"]
        assert r["full_checkpoint_bytes"] == model_bytes
        assert r["artifact_bytes"] == (out / "scenes" / scene / "sray" / "sray_delta.safetensors").stat().st_size

    # MLflow: one parent, one child per scene, statuses, the summary table (and charts) on the parent.
    record = json.loads((out / "fleet.json").read_text())
    parent_id = record["parent_run_id"]
    children = {c.info.run_id: c for c in _children(mlflow_uri, parent_id)}
    assert set(children) == {r["child_run_id"] for r in results}
    status = {c.data.tags["sray.scene"]: c.info.status for c in children.values()}
    assert status == {"synth_train_000": "FINISHED", "synth_train_001": "FAILED", "synth_test_000": "FINISHED"}
    finished = children[by_scene["synth_test_000"]["child_run_id"]]
    params = finished.data.params
    assert params["protocol.stride"] == "4" and params["protocol.source_rule"] == source_rule
    client = _client(mlflow_uri)
    parent = client.get_run(parent_id)
    assert parent.info.status == "FINISHED"
    assert parent.data.metrics["sray/finished"] == 2 and parent.data.metrics["sray/failed"] == 1
    assert parent.data.metrics["sray/miou_after_mean"] == pytest.approx(
        (by_scene["synth_train_000"]["miou_after"] + by_scene["synth_test_000"]["miou_after"]) / 2, abs=1e-12)
    artifacts = {a.path for a in client.list_artifacts(parent_id)}
    assert {"fleet_results.md", "fleet_results.json"} <= artifacts
    table = (out / "fleet_results.md").read_text()
    for scene in SCENES:
        assert f"| {scene} | sray |" in table
    assert "| failed |" in table and "InjectedFailure" in table
    [caption] = [line for line in table.splitlines() if line.startswith("Protocol")]
    assert caption.startswith(f"Protocol: sources: {cfg.finetune.held_out.n_source} per query, fixed, top-ranked by "
                              f"{source_rule}; pixels: every 4th in each direction (stride 4), so no SSIM")
    if importlib.util.find_spec("sray.platform.viz.charts") is not None:
        charts = [a.path for a in client.list_artifacts(parent_id, "charts")]
        assert any(p.endswith(".png") for p in charts)

    # Re-launch (the failure is gone): finished pairs are skipped untouched, the failed one runs again.
    stamps = {s: (out / "scenes" / s / "sray" / "result.json").stat().st_mtime_ns for s in SCENES if s != FAILING}
    again = run_fleet(tiny_fleet_config(), tiny_checkpoint, tiny_shards, SCENES, out, mlflow_uri, ["sray"])
    again_by_scene = {r["scene"]: r for r in again}
    for scene, stamp in stamps.items():
        assert (out / "scenes" / scene / "sray" / "result.json").stat().st_mtime_ns == stamp
        assert again_by_scene[scene] == json.loads(json.dumps(by_scene[scene]))
    assert again_by_scene[FAILING]["status"] == "finished" and again_by_scene[FAILING]["attempts"] == 1
    assert json.loads((out / "fleet.json").read_text())["parent_run_id"] == parent_id
    assert len(_children(mlflow_uri, parent_id)) == 4  # the earlier failed child stays as history


def test_fleet_refuses_an_out_dir_of_another_checkpoint(tiny_shards, tiny_checkpoint, mlflow_uri, tmp_path):
    out = tmp_path / "fleet"
    out.mkdir()
    (out / "fleet.json").write_text(json.dumps({"format": "sray-fleet", "base_sha256": "0" * 64, "tracker": "mlflow",
                                                "tracking_uri": mlflow_uri, "parent_run_id": None, "launches": 1}))
    with pytest.raises(ValueError, match="another checkpoint"):
        run_fleet(tiny_fleet_config(), tiny_checkpoint, tiny_shards, ["synth_test_000"], out, mlflow_uri, ["sray"])


def test_fleet_rejects_unknown_scene_and_method(tiny_shards, tiny_checkpoint, mlflow_uri, tmp_path):
    with pytest.raises(ValueError, match="no scene 'nope'"):
        run_fleet(tiny_fleet_config(), tiny_checkpoint, tiny_shards, ["nope"], tmp_path, mlflow_uri, ["sray"])
    with pytest.raises(ValueError, match="methods"):
        run_fleet(tiny_fleet_config(), tiny_checkpoint, tiny_shards, ["synth_test_000"], tmp_path, mlflow_uri, ["x"])


def test_semantic_nerf_through_the_fleet(ray_session, tiny_shards, tiny_checkpoint, mlflow_uri, tmp_path):
    from sray.platform.finetune.scene_artifacts import load_semantic_nerf

    out = tmp_path / "fleet"
    [result] = run_fleet(tiny_fleet_config(), tiny_checkpoint, tiny_shards, ["synth_test_000"], out, mlflow_uri,
                         ["semantic-nerf"])
    assert set(result) == CONTRACT_KEYS and _on_disk(out, "synth_test_000", "semantic-nerf") == result
    assert result["protocol"] == _protocol("none (per-scene model)", 0, 4)  # renders from no source views
    assert result["status"] == "finished" and result["method"] == "semantic-nerf"
    assert result["curve"][0]["step"] == 0 and result["steps_used"] == 6
    artifact = out / "scenes" / "synth_test_000" / "semantic-nerf" / "semantic_nerf.safetensors"
    net = load_semantic_nerf(artifact)
    assert result["artifact_bytes"] == artifact.stat().st_size
    state_bytes = sum(t.numel() * t.element_size() for t in net.state_dict().values())
    assert state_bytes <= result["artifact_bytes"] < state_bytes + 64 * 1024  # the whole network + a header
    assert net.cfg.depth == 2 and net.cfg.width == 32 and net.cfg.n_classes == 20
    assert _client(mlflow_uri).get_run(result["child_run_id"]).info.status == "FINISHED"
    assert torch.isfinite(torch.tensor([p["psnr"] for p in result["curve"]])).all()


def test_checkpoint_and_scene_lookup(tiny_shards, tiny_checkpoint, tmp_path):
    assert unseen_scenes(tiny_shards) == ["synth_test_000"]
    job_dir = tiny_checkpoint.parent.parent
    for given in (tiny_checkpoint, tiny_checkpoint.parent, job_dir):
        assert resolve_checkpoint(given) == tiny_checkpoint
    with pytest.raises(FileNotFoundError, match="no sray checkpoint here"):
        resolve_checkpoint(tmp_path)
