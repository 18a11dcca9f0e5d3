"""``sray stability`` end to end on the toy preset, from tiny shards and two given tiny checkpoints (full CRA and
``attention=none``): every axis, S-Ray's rows (zero-shot with and without CRA, and finetuned on the scene at the
preset's CPU budget), the clean point against ``sray eval``, an injected NaN recorded as a failure while the rest
completes, resuming without running any trial again, and the tracked runs. (The other methods' rows, and S-Ray's
RGB-D rows beside ``2d-transfer``, are computed without Ray in ``test_stability_models.py``.)
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))
from fleet_fixtures import write_tiny_checkpoint  # noqa: E402
from injected_faults import injected_faults  # noqa: E402
from mlflow_fixtures import mlflow_template, mlflow_uri  # noqa: E402,F401  (pytest fixtures, used by name)
from train_fixtures import tiny_shards  # noqa: E402,F401

from sray.jobs.cli import main  # noqa: E402
from sray.platform.common.bench_doc import Bench, bench_dir  # noqa: E402
from sray.platform.stability.axes import AXES, PRESETS  # noqa: E402

POISONED = "sray/image_noise/30"


@pytest.fixture(scope="module")
def toy_checkpoints(tiny_shards: Path, tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """Tiny step-0 checkpoints of both S-Ray variants the suite compares."""
    root = tmp_path_factory.mktemp("stability-ckpt")
    return {name: write_tiny_checkpoint(tiny_shards, root / name, seed=1, attention=name) for name in ("full", "none")}


def _run(shards: Path, checkpoints: dict[str, Path], out: Path, doc: Path, uri: str, *extra: str) -> int:
    return main(["stability", "--preset", "toy", "--data", str(shards), "--checkpoint", str(checkpoints["full"]),
                 "--checkpoint-no-cra", str(checkpoints["none"]), "--methods", "sray", "--out",
                 str(out), "--doc", str(doc), "--tracking-uri", uri, "--device", "cpu", *extra])


def test_toy_suite_runs_every_axis_records_a_nan_as_failed_and_resumes(ray_session, tiny_shards, toy_checkpoints,
                                                                       mlflow_uri, tmp_path, monkeypatch) -> None:
    out, doc = tmp_path / "suite", tmp_path / "benchmarks.md"
    with injected_faults(f"stability.nan_points={POISONED}"):
        assert _run(tiny_shards, toy_checkpoints, out, doc, mlflow_uri) == 0
        result = json.loads((out / "stability.json").read_text())
        assert result["axes"] == list(AXES)
        points = result["points"]
        methods = {(p["axis"], p["method"]) for p in points}
        assert {m for _, m in methods} == {"sray", "sray-no-cra", "sray-scene"}
        assert ("precision", "sray-scene") not in methods and ("pose_noise", "sray-scene") in methods
        assert ("unseen_rays", "sray-scene") in methods and ("precision", "sray-no-cra") in methods
        budget = PRESETS["toy"].scene_cpu_seconds
        trained = [p for p in points if p["method"].endswith("-scene")]
        assert trained and all(p["seed"] is not None and min(p["cpu_s"]) >= budget for p in trained)
        labels = {r["name"]: r["label"] for r in result["rows"]}
        assert labels["sray-scene"].endswith("[trained on the scene · RGB]")
        assert labels["sray-no-cra"].endswith("[never saw the scene · RGB]")
        poisoned = [p for p in points if (p["method"], p["axis"], p["level"]) == ("sray", "image_noise", 30)]
        assert len(poisoned) == PRESETS["toy"].seeds
        assert all(p["status"] == "failed" and p["error"].startswith("NonFiniteOutput") for p in poisoned)
        others = [p for p in points if p not in poisoned]
        assert others and all(p["status"] == "ok" and p["miou"] is not None for p in others)
        assert any(line.startswith("image_noise / sray: half the clean mIoU lost at 15 (interpolated")
                   for line in result["breaking_points"])
        assert "| 30 | failed |" in (out / "tables" / "image_noise.md").read_text()
        for chart in ("stability_miou.png", "stability_psnr.png"):
            assert (out / chart).stat().st_size > 10_000
            assert (bench_dir(doc, Bench("stability-toy", "Stability, toy")) / chart).exists()
        text = doc.read_text()
        assert text.count("## Stability, toy (") == 1  # one section: a table per axis and the breaking points
        assert text.count("\n### ") == len(AXES) + 1

        # a re-run finds every point stored and starts no trial
        from sray.platform.sweep import engine

        def refuse(*args, **kwargs):
            raise AssertionError("a stored point was computed again")

        monkeypatch.setattr(engine, "run_study", refuse)
        assert _run(tiny_shards, toy_checkpoints, out, doc, mlflow_uri, "--axes", "blur") == 0
        again = json.loads((out / "stability.json").read_text())
        assert [(p["key"], p["miou"]) for p in again["points"]] == [(p["key"], p["miou"]) for p in points]

    import mlflow

    client = mlflow.MlflowClient(mlflow_uri)
    experiment = client.get_experiment_by_name("sray-stability")
    runs = client.search_runs([experiment.experiment_id])
    parents = [r for r in runs if r.data.tags.get("sray.kind") == "stability"]
    children = [r for r in runs if r.data.tags.get("sray.kind") == "stability-axis"]
    assert len(parents) == 2 and len(children) == 2 * len(AXES)
    first = min(parents, key=lambda r: r.info.start_time)
    mine = [c for c in children if c.data.tags.get("mlflow.parentRunId") == first.info.run_id]
    assert sorted(c.data.tags["sray.axis"] for c in mine) == sorted(AXES)
    noise = next(c for c in mine if c.data.tags["sray.axis"] == "image_noise")
    history = client.get_metric_history(noise.info.run_id, "sray-no-cra/miou")
    assert [m.step for m in history] == [0, 1]

    # the clean point is `sray eval` on the same data, stride and sources
    from sray.platform.eval.zero_shot import evaluate_checkpoint

    preset = PRESETS["toy"]
    clean = next(p for p in points if (p["axis"], p["method"], p["level"]) == ("pose_noise", "sray", 0))
    report = evaluate_checkpoint(toy_checkpoints["full"], tiny_shards, None, tmp_path / "eval",
                                 n_source=preset.n_source, stride=preset.eval_stride, tracking_uri=mlflow_uri,
                                 progress=False)
    assert clean["seed"] is None
    assert clean["miou"] == pytest.approx(100 * report["mean"]["dataset_level"]["miou"], abs=1e-9)
    assert clean["psnr"] == pytest.approx(report["mean"]["colour"]["psnr_db"], abs=1e-9)


def test_bad_input_is_one_clear_line(tiny_shards, toy_checkpoints, tmp_path, capsys) -> None:
    assert main(["stability", "--preset", "toy", "--data", str(tmp_path), "--checkpoint",
                 str(toy_checkpoints["full"])]) == 2
    assert "no manifest.json there" in capsys.readouterr().err
    assert main(["stability", "--preset", "toy", "--checkpoint", "/no/such"]) == 2
    assert "/no/such: no such folder" in capsys.readouterr().err
    assert main(["stability", "--preset", "toy", "--data", str(tiny_shards)]) == 2
    assert "need --checkpoint" in capsys.readouterr().err
