"""MLflow run preparation on the embedded SQLite store (through ``runs`` and the ``MlflowTracker``), and
config flattening into MLflow params."""

from __future__ import annotations

import dataclasses
import enum
import logging
import sys
from pathlib import Path

import pytest
from mlflow import MlflowClient

from sray.platform.tracking.mlflow_tracker import MlflowTracker
from sray.platform.tracking.params import MAX_PARAM_VALUE, TRUNCATION_MARKER, flatten_config, to_params
from sray.platform.tracking.runs import (
    PARENT_RUN_TAG,
    artifact_root,
    default_tracking_uri,
    find_run,
    prepare_run,
    sqlite_path,
)
from sray.platform.tracking.tracker import RunHandle

sys.path.insert(0, str(Path(__file__).resolve().parent))
from mlflow_fixtures import mlflow_template, mlflow_uri  # noqa: E402,F401  (pytest fixtures, used by name)


def test_default_store_lives_in_the_working_directory(tmp_path, monkeypatch, mlflow_template):
    monkeypatch.chdir(tmp_path)
    uri = default_tracking_uri(Path("work"))
    assert uri == f"sqlite:///{tmp_path / 'work' / 'mlflow.db'}"
    assert sqlite_path(uri) == tmp_path / "work" / "mlflow.db"
    assert artifact_root(uri) == tmp_path / "work" / "mlartifacts"
    assert sqlite_path("http://mlflow:5000") is None
    (tmp_path / "work").mkdir()
    (tmp_path / "work" / "mlflow.db").write_bytes(mlflow_template.read_bytes())
    handle = prepare_run(uri, "e", "r")  # no artifact root given: artifacts beside the database
    run = MlflowClient(uri).get_run(handle.run_id)
    assert run.info.artifact_uri.startswith((tmp_path / "work" / "mlartifacts" / "e").as_uri() + "/")


def test_prepare_find_resume_and_nesting(mlflow_uri, tmp_path):
    uri = mlflow_uri
    parent = prepare_run(uri, "sray train", "fleet-1", tags={"kind": "fleet"})
    child = prepare_run(uri, "sray train", "scene0000", tags={"scene": "scene0000"}, parent_run_id=parent.run_id)
    client = MlflowClient(uri)
    experiment = client.get_experiment(parent.experiment_id)
    assert experiment.name == "sray train" and child.experiment_id == parent.experiment_id
    assert experiment.artifact_location == (tmp_path / "mlartifacts" / "sray_train").as_uri()
    run = client.get_run(child.run_id)
    assert run.info.run_name == "scene0000" and run.info.status == "RUNNING"
    assert run.data.tags[PARENT_RUN_TAG] == parent.run_id and run.data.tags["scene"] == "scene0000"
    assert child.ui_url == f"http://127.0.0.1:5000/#/experiments/{child.experiment_id}/runs/{child.run_id}"
    assert f"--backend-store-uri {uri}" in child.ui_hint

    assert child.tracker == "mlflow" and child.store == uri

    tracker = MlflowTracker(uri)
    assert find_run(uri, "sray train", "scene0000") == child == tracker.find_run("sray train", "scene0000")
    assert find_run(uri, "sray train", "nope") is None and find_run(uri, "other", "scene0000") is None
    assert tracker.get_run(child.run_id) == child
    assert tracker.end_run(child, "FAILED")
    assert client.get_run(child.run_id).info.status == "FAILED"
    assert tracker.resume_run("sray train", "scene0000").run_id == child.run_id
    assert client.get_run(child.run_id).info.status == "RUNNING"
    with pytest.raises(LookupError, match="no MLflow run named 'ghost'"):
        tracker.resume_run("sray train", "ghost")
    assert tracker.tag_run(child, {"sray.error": "x" * 6000})
    assert client.get_run(child.run_id).data.tags["sray.error"] == "x" * 5000  # cut to MLflow's limit


def test_tracker_problems_only_warn(tmp_path, caplog):
    blocker = tmp_path / "file"
    blocker.write_text("not a folder")
    tracker = MlflowTracker(f"sqlite:///{blocker}/sub/mlflow.db")
    handle = RunHandle(tracker="mlflow", store=tracker.store, run_id="0" * 32)
    with caplog.at_level(logging.WARNING, logger="sray.platform.tracking.tracker"):
        assert not tracker.end_run(handle, "FINISHED") and not tracker.tag_run(handle, {"a": "b"})
    assert "could not mark MLflow run" in caplog.text and "could not tag MLflow run" in caplog.text


def test_server_uri_links_to_the_server():
    from sray.platform.tracking.runs import run_handle

    handle = run_handle("http://mlflow:5000/", "3", "abc")
    assert handle.ui_url == "http://mlflow:5000/#/experiments/3/runs/abc" and handle.ui_hint == ""


def test_unusable_store_names_the_uri(tmp_path):
    blocker = tmp_path / "file"
    blocker.write_text("not a folder")
    with pytest.raises(ConnectionError, match="not usable"):
        prepare_run(f"sqlite:///{blocker}/sub/mlflow.db", "e", "r")


class Precision(enum.Enum):
    BF16 = "bf16"


@dataclasses.dataclass
class Optim:
    lr: float = 1e-3
    betas: tuple[float, float] = (0.9, 0.999)


@dataclasses.dataclass
class Config:
    optim: Optim = dataclasses.field(default_factory=Optim)
    precision: Precision = Precision.BF16
    data: Path = Path("/data/shards")
    scenes: list = dataclasses.field(default_factory=lambda: [{"name": "a", "views": 3}, {"name": "b", "views": 4}])
    extra: dict = dataclasses.field(default_factory=lambda: {"note": None, "odd key!": 1})


def test_flatten_uses_dotted_keys_and_readable_values():
    assert flatten_config({"model": {"tau": 0.7}, "views": [1, 2]}) == {"model.tau": 0.7, "views": [1, 2]}
    params = to_params(Config())
    assert params == {"optim.lr": "0.001", "optim.betas": "[0.9, 0.999]", "precision": "bf16",
                      "data": "/data/shards", "scenes.0.name": "a", "scenes.0.views": "3", "scenes.1.name": "b",
                      "scenes.1.views": "4", "extra.note": "None", "extra.odd key_": "1"}


def test_long_values_are_truncated_with_a_warning(caplog):
    with caplog.at_level(logging.WARNING):
        params = to_params({"short": "x", "long": "y" * (MAX_PARAM_VALUE + 50)})
    assert params["short"] == "x"
    assert len(params["long"]) == MAX_PARAM_VALUE and params["long"].endswith(TRUNCATION_MARKER)
    assert "'long'" in caplog.text and str(MAX_PARAM_VALUE + 50) in caplog.text
