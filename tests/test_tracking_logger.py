"""MlflowRunLogger: batched delivery into the fixed run, registration, and no crash when the store is down."""

from __future__ import annotations

import dataclasses
import logging
import socket
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import torch
from mlflow import MlflowClient

from sray.platform.tracking.logger import MlflowRunLogger
from sray.platform.tracking.registry import open_logger
from sray.platform.tracking.runs import prepare_run
from sray.platform.tracking.tracker import RunHandle

sys.path.insert(0, str(Path(__file__).resolve().parent))
from mlflow_fixtures import mlflow_template, mlflow_uri  # noqa: E402,F401  (pytest fixtures, used by name)


class CountingClient:
    """A real MlflowClient that counts log_batch calls and fails the first ``fail_first`` calls."""

    def __init__(self, uri: str, fail_first: int = 0) -> None:
        self.real = MlflowClient(uri, registry_uri=uri)
        self.fail_left = fail_first
        self.batches = 0

    def __getattr__(self, name):
        method = getattr(self.real, name)

        def call(*args, **kwargs):
            if self.fail_left > 0:
                self.fail_left -= 1
                raise ConnectionError("connection refused (simulated)")
            if name == "log_batch":
                self.batches += 1
            return method(*args, **kwargs)

        return call


@dataclasses.dataclass
class Optim:
    lr: float = 1e-3
    steps: int = 100


@dataclasses.dataclass
class TrainCfg:
    optim: Optim = dataclasses.field(default_factory=Optim)
    name: str = "synth-small"


def _history(uri: str, run_id: str, key: str) -> list[tuple[int, float]]:
    return sorted((m.step, m.value) for m in MlflowClient(uri).get_metric_history(run_id, key))


def test_everything_lands_in_the_fixed_run_in_batches(mlflow_uri, tmp_path):
    """Params, metrics, a file, an image and a registered checkpoint reach the run in few batches."""
    handle = prepare_run(mlflow_uri, "sray train", "job-a")
    client = CountingClient(mlflow_uri)
    png = tmp_path / "render.png"
    png.write_bytes(b"\x89PNG\r\n\x1a\n fake but a file")
    ckpt = tmp_path / "step_000000050"
    ckpt.mkdir()
    (ckpt / "state.pt").write_bytes(b"weights")
    config = tmp_path / "config.json"
    config.write_text('{"optim": {"lr": 0.001}}\n')
    with MlflowRunLogger(handle, flush_every_steps=10, flush_every_s=3600, client=client) as logger:
        logger.log_params(TrainCfg())
        for step in range(50):
            logger.log_metrics({"loss": 1.0 / (step + 1), "lr": torch.tensor(0.5)}, step=step)
        logger.log_artifact(config)
        logger.log_image(png)
        assert logger.register_model(ckpt, "sray-test", alias="best") == "1"
    assert client.batches <= 1 + 6  # one params batch + a metric batch every 10 steps (+ the final one)

    real = MlflowClient(mlflow_uri, registry_uri=mlflow_uri)
    run = real.get_run(handle.run_id)
    assert run.info.status == "FINISHED"
    assert run.data.params == {"optim.lr": "0.001", "optim.steps": "100", "name": "synth-small"}
    assert _history(mlflow_uri, handle.run_id, "loss") == [(s, 1.0 / (s + 1)) for s in range(50)]
    assert [s for s, _ in _history(mlflow_uri, handle.run_id, "lr")] == list(range(50))
    artifacts = {a.path for a in real.list_artifacts(handle.run_id)}
    assert artifacts == {"config.json", "renders", "checkpoint"}
    assert [a.path for a in real.list_artifacts(handle.run_id, "checkpoint")] == ["checkpoint/state.pt"]
    version = real.get_model_version_by_alias("sray-test", "best")
    assert str(version.version) == "1" and version.run_id == handle.run_id


def test_restarted_logger_continues_the_same_run(mlflow_uri):
    handle = prepare_run(mlflow_uri, "sray train", "job-b")
    first = MlflowRunLogger(handle, flush_every_steps=1)
    for step in range(4):
        first.log_metrics({"loss": float(step)}, step=step)
    # the worker dies here (no close); Ray restarts the group, rank 0 resumes from step 2 and opens a
    # logger on the handle's fields through the tracker registry, as train_worker does
    second = open_logger(RunHandle(**dataclasses.asdict(handle)), flush_every_steps=1)
    assert isinstance(second, MlflowRunLogger) and second.handle == handle
    for step in range(2, 6):
        second.log_metrics({"loss": float(step)}, step=step)
    second.close()
    steps = sorted({s for s, _ in _history(mlflow_uri, handle.run_id, "loss")})
    assert steps == list(range(6))  # repeats allowed, no gap
    assert len(MlflowClient(mlflow_uri).search_runs([handle.experiment_id])) == 1


def _closed_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_unreachable_server_warns_once_and_never_raises(tmp_path, caplog):
    uri = f"http://127.0.0.1:{_closed_port()}"
    handle = RunHandle(tracker="mlflow", store=uri, run_id="0" * 32, experiment_id="1", ui_url=uri)
    png = tmp_path / "x.png"
    png.write_bytes(b"png")
    start = time.perf_counter()
    with caplog.at_level(logging.WARNING, logger="sray.platform.tracking.logger"):
        logger = MlflowRunLogger(handle, flush_every_steps=1, retry_initial_s=0.0, close_timeout_s=0.0)
        logger.log_params({"a": 1})
        for step in range(20):
            logger.log_metrics({"loss": 0.5}, step=step)
        logger.log_image(png)
        assert logger.register_model(png, "m") is None
        logger.close("FINISHED")
    assert time.perf_counter() - start < 10.0
    unreachable = [r for r in caplog.records if "unreachable while sending" in r.getMessage()]
    assert len(unreachable) == 1 and uri in unreachable[0].getMessage()
    assert logger.pending()["metrics"] == 20 and logger.pending()["params"] == 1


def test_close_keeps_retrying_until_a_restarted_server_answers(mlflow_uri):
    handle = prepare_run(mlflow_uri, "sray train", "job-r")
    client = CountingClient(mlflow_uri, fail_first=8)  # down for the whole run and 3 close attempts
    logger = MlflowRunLogger(handle, flush_every_steps=1, retry_initial_s=0.0, close_timeout_s=30.0,
                             close_poll_s=0.1, client=client)
    for step in range(5):
        logger.log_metrics({"loss": float(step)}, step=step)
    assert logger.pending()["metrics"] == 5
    logger.close()
    assert _history(mlflow_uri, handle.run_id, "loss") == [(s, float(s)) for s in range(5)]
    assert MlflowClient(mlflow_uri).get_run(handle.run_id).info.status == "FINISHED"


def test_buffered_items_are_delivered_after_an_outage(mlflow_uri, caplog):
    handle = prepare_run(mlflow_uri, "sray train", "job-c")
    client = CountingClient(mlflow_uri, fail_first=4)
    with caplog.at_level(logging.WARNING, logger="sray.platform.tracking.logger"):
        logger = MlflowRunLogger(handle, flush_every_steps=1, retry_initial_s=0.0, client=client)
        for step in range(10):
            logger.log_metrics({"loss": float(step)}, step=step)
        logger.close()
    assert _history(mlflow_uri, handle.run_id, "loss") == [(s, float(s)) for s in range(10)]
    assert sum("unreachable" in r.getMessage() for r in caplog.records) == 1
    assert MlflowClient(mlflow_uri).get_run(handle.run_id).info.status == "FINISHED"


def test_backoff_skips_attempts_until_it_expires(mlflow_uri):
    handle = prepare_run(mlflow_uri, "sray train", "job-d")
    client = CountingClient(mlflow_uri, fail_first=1)
    logger = MlflowRunLogger(handle, flush_every_steps=1, retry_initial_s=0.3, client=client)
    logger.log_metrics({"loss": 1.0}, step=0)  # fails: next attempt in 0.3 s
    logger.log_metrics({"loss": 2.0}, step=1)  # inside the back-off window: not even tried
    assert client.fail_left == 0 and client.batches == 0 and logger.pending()["metrics"] == 2
    time.sleep(0.35)
    logger.log_metrics({"loss": 3.0}, step=2)
    assert client.batches == 1 and logger.pending()["metrics"] == 0


def test_unsent_metrics_are_those_the_store_has_not_got(mlflow_uri):
    handle = prepare_run(mlflow_uri, "sray train", "job-u")
    client = CountingClient(mlflow_uri, fail_first=1)
    logger = MlflowRunLogger(handle, flush_every_steps=1, retry_initial_s=60.0, client=client)
    logger.log_metrics({"loss": 1.5, "lr": 0.5}, step=3)  # the store refuses: both stay buffered
    assert logger.unsent_metrics() == [("loss", 1.5, 3), ("lr", 0.5, 3)]
    assert logger.flush(force=True) and logger.unsent_metrics() == []
    assert _history(mlflow_uri, handle.run_id, "loss") == [(3, 1.5)]


def test_bounded_buffer_drops_oldest_with_a_warning(caplog):
    uri = f"http://127.0.0.1:{_closed_port()}"
    handle = RunHandle(tracker="mlflow", store=uri, run_id="0" * 32, experiment_id="1", ui_url=uri)
    with caplog.at_level(logging.WARNING, logger="sray.platform.tracking.logger"):
        logger = MlflowRunLogger(handle, flush_every_steps=1000, max_buffered_metrics=5)
        for step in range(12):
            logger.log_metrics({"loss": float(step)}, step=step)
    assert logger.pending()["metrics"] == 5
    assert [m.step for m in logger._metrics] == list(range(7, 12))
    assert sum("buffer is full" in r.getMessage() for r in caplog.records) == 1


def test_refused_param_is_dropped_and_metrics_still_arrive(mlflow_uri, caplog):
    handle = prepare_run(mlflow_uri, "sray train", "job-e")
    MlflowClient(mlflow_uri).log_param(handle.run_id, "optim.lr", "0.5")  # an earlier job used another lr
    with caplog.at_level(logging.WARNING, logger="sray.platform.tracking.logger"):
        with MlflowRunLogger(handle) as logger:
            logger.log_params({"optim": {"lr": 1e-3}})
            logger.log_metrics({"miou": np.float32(0.25)}, step=0)
    assert "refused params" in caplog.text
    assert _history(mlflow_uri, handle.run_id, "miou") == [(0, 0.25)]


def test_exception_inside_the_block_marks_the_run_failed(mlflow_uri):
    handle = prepare_run(mlflow_uri, "sray train", "job-f")
    with pytest.raises(RuntimeError):
        with MlflowRunLogger(handle):
            raise RuntimeError("training diverged")
    assert MlflowClient(mlflow_uri).get_run(handle.run_id).info.status == "FAILED"
