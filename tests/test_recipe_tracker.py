"""The tracker registry, and the recipe "add a tracker": a JSON-lines tracker defined here, registered,
and driven by the real ``sray eval`` command; what it recorded is checked against metrics.json."""

from __future__ import annotations

import json
import shutil
import uuid
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import Any

import pytest
from fleet_fixtures import tiny_checkpoint  # noqa: F401
from train_fixtures import tiny_shards  # noqa: F401

from sray.platform.config.train_config import TrainConfig
from sray.platform.tracking.mlflow_tracker import MlflowTracker
from sray.platform.tracking.params import flatten_config
from sray.platform.tracking.registry import TRACKERS, get_tracker, open_logger, register_tracker
from sray.platform.tracking.tracker import RunHandle, RunLogger, Tracker


class JsonlLogger(RunLogger):
    """Appends every call as one JSON line to ``<store>/<run id>.jsonl``; artifacts are copied beside it."""

    def __init__(self, handle: RunHandle) -> None:
        self.handle = handle
        self.folder = Path(handle.store)

    def _event(self, **event: Any) -> None:
        with open(self.folder / f"{self.handle.run_id}.jsonl", "a") as f:
            f.write(json.dumps(event, default=str) + "\n")

    def log_params(self, config: Any) -> None:
        self._event(kind="params", params={k: str(v) for k, v in flatten_config(config).items()})

    def log_metrics(self, metrics: Mapping[str, Any], step: int) -> None:
        self._event(kind="metrics", step=step, values={k: float(v) for k, v in metrics.items()})

    def log_artifact(self, path: Path, artifact_path: str | None = None) -> None:
        target = self.folder / self.handle.run_id / (artifact_path or "") / Path(path).name
        if Path(path).is_dir():
            shutil.copytree(path, target.parent, dirs_exist_ok=True)
        else:
            target.parent.mkdir(parents=True, exist_ok=True)
            shutil.copyfile(path, target)
        self._event(kind="artifact", path=str(path), artifact_path=artifact_path)

    def register_model(self, checkpoint: Path, name: str, alias: str = "latest") -> str | None:
        self._event(kind="model", checkpoint=str(checkpoint), name=name, alias=alias)
        return "1"

    def close(self, status: str = "FINISHED") -> None:
        self._event(kind="status", status=status)


class JsonlTracker(Tracker):
    """Runs as JSON-lines files in a folder (the store)."""

    name = "jsonl"
    label = "JSON-lines"

    @classmethod
    def default_store(cls, workdir: Path) -> str:
        return str(Path(workdir).resolve() / "runs")

    def ensure_store(self) -> None:
        Path(self.store).mkdir(parents=True, exist_ok=True)

    def _events(self, run_id: str) -> list[dict[str, Any]]:
        return [json.loads(line) for line in (Path(self.store) / f"{run_id}.jsonl").read_text().splitlines()]

    def start_run(self, experiment: str, run_name: str, tags: Mapping[str, str] | None = None,
                  parent: RunHandle | None = None) -> RunHandle:
        self.ensure_store()
        handle = RunHandle(tracker=self.name, store=self.store, run_id=uuid.uuid4().hex, experiment_id=experiment)
        self.logger(handle)._event(kind="start", experiment=experiment, name=run_name, tags=dict(tags or {}),
                                   parent=parent.run_id if parent else None)
        return handle

    def find_run(self, experiment: str, run_name: str) -> RunHandle | None:
        for path in sorted(Path(self.store).glob("*.jsonl")):
            start = self._events(path.stem)[0]
            if (start["experiment"], start["name"]) == (experiment, run_name):
                return self.get_run(path.stem)
        return None

    def get_run(self, run_id: str) -> RunHandle:
        start = self._events(run_id)[0]  # FileNotFoundError: no such run
        return RunHandle(tracker=self.name, store=self.store, run_id=run_id, experiment_id=start["experiment"])

    def set_status(self, handle: RunHandle, status: str) -> None:
        self.logger(handle)._event(kind="status", status=status)

    def set_tags(self, handle: RunHandle, tags: Mapping[str, str]) -> None:
        self.logger(handle)._event(kind="tags", tags=dict(tags))

    def logger(self, handle: RunHandle, **options: Any) -> JsonlLogger:
        return JsonlLogger(handle)


@pytest.fixture
def jsonl_tracker() -> Iterator[type[JsonlTracker]]:
    """The JSON-lines tracker, registered for one test."""
    register_tracker(JsonlTracker)
    yield JsonlTracker
    TRACKERS.pop(JsonlTracker.name)


def test_mlflow_is_the_default_and_unknown_names_are_refused(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    tracker = get_tracker()
    assert isinstance(tracker, MlflowTracker) and tracker.store == f"sqlite:///{tmp_path / 'mlflow.db'}"
    assert get_tracker("mlflow", "http://mlflow:5000").store == "http://mlflow:5000"
    assert TrainConfig().run.tracker == "mlflow"
    with pytest.raises(ValueError, match=r"unknown tracker 'wandb'; known: \['mlflow'\]"):
        get_tracker("wandb")
    assert not (tmp_path / "mlflow.db").exists()  # choosing a tracker touches no store


def test_add_a_tracker_and_evaluate_through_it(jsonl_tracker, tiny_checkpoint, tiny_shards, tmp_path, capsys):
    from sray.jobs.cli import main

    store, out = tmp_path / "runs", tmp_path / "eval"
    assert main(["eval", "--checkpoint", str(tiny_checkpoint), "--data", str(tiny_shards), "--n-source", "3",
                 "--stride", "4", "--out", str(out), "--tracker", "jsonl", "--tracking-uri", str(store)]) == 0
    [log] = store.glob("*.jsonl")
    events = [json.loads(line) for line in log.read_text().splitlines()]
    start, params, metrics, status = events[0], events[1], events[2], events[-1]
    assert start["kind"] == "start" and start["experiment"] == "sray-eval" and start["tags"]["sray.kind"] == "eval"
    assert "stride 4" in start["tags"]["sray.protocol"] and start["parent"] is None
    assert params["kind"] == "params" and params["params"]["protocol.stride"] == "4"
    assert params["params"]["protocol.n_source"] == "3" and params["params"]["checkpoint"] == str(tiny_checkpoint)

    # every score of metrics.json (read here, not through the eval code) arrived at the checkpoint's step
    report = json.loads((out / "metrics.json").read_text())
    assert metrics["kind"] == "metrics" and metrics["step"] == report["checkpoint_step"] == 0
    for name, block in [*report["scenes"].items(), ("mean", report["mean"])]:
        assert metrics["values"][f"{name}/miou"] == block["dataset_level"]["miou"]
        assert metrics["values"][f"{name}/miou_per_image"] == block["per_image"]["miou"]
        assert metrics["values"][f"{name}/psnr"] == block["colour"]["psnr_db"]
        assert f"{name}/ssim" not in metrics["values"]  # strided: no SSIM
    stored = store / log.stem
    assert json.loads((stored / "metrics.json").read_text()) == report
    for scene in report["scenes"]:
        view = report["scenes"][scene]["views"][0]
        assert (stored / "renders" / scene / Path(view["pngs"]["panel"]).name).read_bytes() == \
            (out / view["pngs"]["panel"]).read_bytes()
    assert status == {"kind": "status", "status": "FINISHED"}
    assert "[sray] jsonl run: " in capsys.readouterr().out

    # the interface's own helpers work on the new tracker: resume a run by name, log through the registry
    tracker = get_tracker("jsonl", str(store))
    handle = tracker.resume_run("sray-eval", start["name"])
    assert handle.run_id == log.stem and json.loads(log.read_text().splitlines()[-1])["status"] == "RUNNING"
    with open_logger(handle) as logger:
        logger.log_image(out / "metrics.json")
    assert (stored / "renders" / "metrics.json").is_file()
    assert json.loads(log.read_text().splitlines()[-1]) == {"kind": "status", "status": "FINISHED"}
    with pytest.raises(LookupError, match="no JSON-lines run named 'ghost'"):
        tracker.resume_run("sray-eval", "ghost")
    assert not tracker.end_run(RunHandle("jsonl", str(tmp_path / "absent" / "x"), "nope"), "FAILED")  # only warns
