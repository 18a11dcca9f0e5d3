"""MLflow as a :class:`~sray.platform.tracking.tracker.Tracker`; ``mlflow`` is imported only when a store is used."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

from sray.platform.tracking import runs
from sray.platform.tracking.tracker import RunHandle, RunLogger, Tracker

TAG_VALUE_LIMIT = 5000


class MlflowTracker(Tracker):
    """Runs in an MLflow store: a ``sqlite:///`` file (the embedded default) or an ``http(s)://`` server."""

    name = runs.NAME
    label = "MLflow"

    @classmethod
    def default_store(cls, workdir: Path) -> str:
        """``sqlite:///<abs workdir>/mlflow.db`` (artifacts under ``<workdir>/mlartifacts``)."""
        return runs.default_tracking_uri(workdir)

    def ensure_store(self) -> None:
        """Create the SQLite schema (or reach the server) now; ConnectionError names the URI."""
        runs.ensure_store(self.store)

    def start_run(self, experiment: str, run_name: str, tags: Mapping[str, str] | None = None,
                  parent: RunHandle | None = None) -> RunHandle:
        """A new RUNNING MLflow run (the experiment is created or restored as needed)."""
        return runs.prepare_run(self.store, experiment, run_name, tags=dict(tags or {}),
                                parent_run_id=parent.run_id if parent else None)

    def find_run(self, experiment: str, run_name: str) -> RunHandle | None:
        """The newest run of that name in the experiment, or None."""
        return runs.find_run(self.store, experiment, run_name)

    def get_run(self, run_id: str) -> RunHandle:
        """The handle of run ``run_id``; MlflowException when the store has no such run."""
        run = runs.mlflow_client(self.store).get_run(run_id)
        return runs.run_handle(self.store, run.info.experiment_id, run.info.run_id)

    def set_status(self, handle: RunHandle, status: str) -> None:
        """RUNNING reopens a run; FINISHED, FAILED and KILLED terminate it (with an end time)."""
        client = runs.mlflow_client(handle.store)
        if status == "RUNNING":
            client.update_run(handle.run_id, status="RUNNING")
        else:
            client.set_terminated(handle.run_id, status=status)

    def set_tags(self, handle: RunHandle, tags: Mapping[str, str]) -> None:
        """Set each tag (values cut to :data:`TAG_VALUE_LIMIT` characters)."""
        client = runs.mlflow_client(handle.store)
        for key, value in tags.items():
            client.set_tag(handle.run_id, key, str(value)[:TAG_VALUE_LIMIT])

    def logger(self, handle: RunHandle, **options: Any) -> RunLogger:
        """A :class:`~sray.platform.tracking.logger.MlflowRunLogger` (``options``: its batching settings)."""
        from sray.platform.tracking.logger import MlflowRunLogger

        return MlflowRunLogger(handle, **options)
