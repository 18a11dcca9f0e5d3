"""MLflow's :class:`~sray.platform.tracking.tracker.RunLogger`: batched (a SQLite write costs more than a training
step), retrying with back-off after a transient failure (warned once), dropping what the store refuses. Not
thread-safe."""

from __future__ import annotations

import logging
import os
import time
from collections import deque
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

from mlflow import MlflowClient
from mlflow.entities import Metric, Param
from mlflow.exceptions import MlflowException
from mlflow.system_metrics.system_metrics_monitor import SystemMetricsMonitor

from sray.platform.tracking.params import sanitize_key, to_params
from sray.platform.tracking.tracker import DRAIN_TIMEOUT_S, RunHandle, RunLogger

log = logging.getLogger(__name__)

PARAMS_PER_BATCH, METRICS_PER_BATCH = 100, 1000
"""MLflow's limits per ``log_batch`` call."""
PERMANENT_ERROR_CODES = frozenset({"INVALID_PARAMETER_VALUE", "RESOURCE_DOES_NOT_EXIST",
                                   "RESOURCE_ALREADY_EXISTS", "BAD_REQUEST", "INVALID_STATE"})
"""MLflow error codes that retrying cannot fix: the item is dropped with a warning."""
HTTP_DEFAULTS = {"MLFLOW_HTTP_REQUEST_MAX_RETRIES": "0", "MLFLOW_HTTP_REQUEST_TIMEOUT": "30"}
"""Set (if unset): MLflow's own HTTP retries would stall training for minutes; this logger retries later instead."""


class MlflowRunLogger(RunLogger):
    """Logs params, metrics, artifacts and a registered model into one fixed MLflow run."""

    def __init__(self, handle: RunHandle, *, flush_every_steps: int = 20, flush_every_s: float = 30.0,
                 max_buffered_metrics: int = 100_000, retry_initial_s: float = 2.0, retry_max_s: float = 300.0,
                 close_timeout_s: float = DRAIN_TIMEOUT_S, close_poll_s: float = 2.0, client: Any = None) -> None:
        """``client``: an ``MlflowClient`` for ``handle.store`` (None: built here)."""
        for key, value in HTTP_DEFAULTS.items():
            os.environ.setdefault(key, value)
        self.handle, self.flush_every_steps, self.flush_every_s = handle, flush_every_steps, flush_every_s
        self.retry_initial_s, self.retry_max_s = retry_initial_s, retry_max_s
        self.close_timeout_s, self.close_poll_s = close_timeout_s, close_poll_s
        self.registered: dict[str, str] = {}
        """Registered model name -> version, filled once a registration went through."""
        self._client = client
        self._params: dict[str, str] = {}
        self._metrics: deque = deque(maxlen=max_buffered_metrics)
        self._ops: deque[tuple[str, Callable[[Any], None]]] = deque(maxlen=1000)
        self._last_flush_step: int | None = None
        self._last_flush_time, self._next_attempt, self._delay = time.monotonic(), 0.0, retry_initial_s
        self._unreachable, self._dropped, self._closed = False, 0, False

    def log_params(self, config: Any) -> None:
        """Flatten a (nested) config dataclass or dict into dotted params and send them now."""
        self._params.update(to_params(config))
        self.flush()

    def log_metrics(self, metrics: Mapping[str, Any], step: int) -> None:
        """Buffer scalar metrics (floats, ints or 0-d tensors) at ``step``; flushes every N steps/s."""
        timestamp = int(time.time() * 1000)
        for key, value in metrics.items():
            number = float(value.item() if hasattr(value, "item") else value)
            if len(self._metrics) == self._metrics.maxlen:
                self._dropped += 1
                if self._dropped == 1:
                    log.warning("MLflow metric buffer is full (%d); dropping the oldest buffered metrics until "
                                "%s is reachable", self._metrics.maxlen, self.handle.store)
            self._metrics.append(Metric(key=sanitize_key(key), value=number, timestamp=timestamp, step=int(step)))
        due_steps = self._last_flush_step is None or step - self._last_flush_step >= self.flush_every_steps
        if due_steps or time.monotonic() - self._last_flush_time >= self.flush_every_s:
            self._last_flush_step = step
            self.flush()

    def log_artifact(self, path: Path, artifact_path: str | None = None) -> None:
        """Upload a file or a folder's contents (under ``artifact_path``); the file must stay until close()."""
        path = Path(path)
        if path.is_dir():
            self._queue(f"artifacts {path}", lambda c: c.log_artifacts(self.handle.run_id, str(path), artifact_path))
        else:
            self._queue(f"artifact {path}", lambda c: c.log_artifact(self.handle.run_id, str(path), artifact_path))
        self.flush()

    def register_model(self, checkpoint: Path, name: str, alias: str = "latest") -> str | None:
        """Upload a checkpoint and register it as ``name@alias``; its version, or None while the store is down."""
        self.log_artifact(checkpoint, "checkpoint")
        source = f"runs:/{self.handle.run_id}/checkpoint"
        created: list[str] = []  # the version, once made: a retry after a failed alias does not make another

        def register(client: Any) -> None:
            if not created:
                try:
                    client.create_registered_model(name)
                except MlflowException as e:
                    if e.error_code != "RESOURCE_ALREADY_EXISTS":
                        raise
                created.append(str(client.create_model_version(name, source=source, run_id=self.handle.run_id).version))
            client.set_registered_model_alias(name, alias, created[0])
            self.registered[name] = created[0]

        self._queue(f"model registration {name}@{alias}", register)
        self.flush()
        return self.registered.get(name)

    def flush(self, force: bool = False) -> bool:
        """Send what is buffered; True when nothing is left. Skipped while backing off unless ``force``."""
        if not force and time.monotonic() < self._next_attempt:
            return False
        self._last_flush_time = time.monotonic()
        client = self._get_client()
        if client is None:
            return False
        while self._params:
            chunk = dict(list(self._params.items())[:PARAMS_PER_BATCH])
            params = [Param(k, v) for k, v in chunk.items()]
            if not self._attempt("params", lambda: client.log_batch(self.handle.run_id, params=params)):
                return False
            for key in chunk:
                self._params.pop(key, None)
        while self._metrics:
            batch = [self._metrics[i] for i in range(min(METRICS_PER_BATCH, len(self._metrics)))]
            if not self._attempt("metrics", lambda: client.log_batch(self.handle.run_id, metrics=batch)):
                return False
            for _ in batch:
                self._metrics.popleft()
        while self._ops:
            what, op = self._ops[0]
            if not self._attempt(what, lambda: op(client)):
                return False
            self._ops.popleft()
        return True

    def unsent_metrics(self) -> list[tuple[str, float, int]]:
        """The buffered metrics, oldest first, as ``(key, value, step)``."""
        return [(m.key, float(m.value), int(m.step)) for m in self._metrics]

    def pending(self) -> dict[str, int]:
        """Counts of buffered params, metrics and other operations not delivered yet."""
        return {"params": len(self._params), "metrics": len(self._metrics), "ops": len(self._ops)}

    def close(self, status: str = "FINISHED") -> None:
        """Deliver everything (retrying for up to ``close_timeout_s``) and mark the run FINISHED, FAILED or KILLED."""
        if self._closed:
            return
        self._queue(f"run status {status}", lambda c: c.set_terminated(self.handle.run_id, status=status))
        if not self.drain(self.close_timeout_s, self.close_poll_s):
            log.warning("MLflow run %s closed with undelivered items %s (tracking store %s unreachable)",
                        self.handle.run_id, self.pending(), self.handle.store)
        self._closed = True

    def watch_system(self, node: str, interval_s: float) -> Callable[[], None]:
        """MLflow's system-metrics monitor on this run (``system/<node>/...``, its steps continued after a restart)."""
        monitor = SystemMetricsMonitor(self.handle.run_id, sampling_interval=interval_s, resume_logging=True,
                                       node_id=node, tracking_uri=self.handle.store)
        monitor.start()
        return monitor.finish

    def _queue(self, what: str, op: Callable[[Any], None]) -> None:
        if len(self._ops) == self._ops.maxlen:
            log.warning("MLflow operation queue is full; dropping %s", self._ops[0][0])
        self._ops.append((what, op))

    def _get_client(self) -> Any:
        if self._client is None:
            try:
                self._client = MlflowClient(tracking_uri=self.handle.store, registry_uri=self.handle.store)
            except Exception as e:  # noqa: BLE001 - tracking never crashes training
                self._transient_failure("connect", e)
        return self._client

    def _attempt(self, what: str, call: Callable[[], Any]) -> bool:
        """Run one MLflow call; True on success or on a permanent (dropped) failure."""
        try:
            call()
        except Exception as e:  # noqa: BLE001 - tracking never crashes training
            if getattr(e, "error_code", None) in PERMANENT_ERROR_CODES:
                log.warning("MLflow refused %s for run %s, dropping it: %s", what, self.handle.run_id, e)
                return True
            self._transient_failure(what, e)
            return False
        if self._unreachable:
            log.info("MLflow tracking store %s is reachable again; sending buffered items", self.handle.store)
            self._unreachable = False
        self._delay, self._next_attempt = self.retry_initial_s, 0.0
        return True

    def _transient_failure(self, what: str, error: Exception) -> None:
        if not self._unreachable:
            log.warning("MLflow tracking store %s unreachable while sending %s (%s); training continues, "
                        "tracking data is buffered and retried with back-off", self.handle.store, what,
                        str(error).splitlines()[0][:300] if str(error) else type(error).__name__)
            self._unreachable = True
        self._next_attempt = time.monotonic() + self._delay
        self._delay = min(self._delay * 2.0, self.retry_max_s)
