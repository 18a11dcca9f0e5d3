"""MLflow runs prepared by a driver before any Ray worker starts (processes creating one SQLite store at once
corrupt it). Default store: ``<workdir>/mlflow.db``, artifacts under ``<workdir>/mlartifacts`` (always explicit)."""

from __future__ import annotations

import logging
import re
import urllib.error
import urllib.request
from pathlib import Path
from typing import Any

from sray.platform.tracking.tracker import RunHandle

log = logging.getLogger(__name__)

NAME = "mlflow"
DEFAULT_UI_PORT = 5000

PARENT_RUN_TAG = "mlflow.parentRunId"
"""MLflow's tag that nests a run under a parent (a fleet's scene runs)."""
EXPERIMENT_KIND_TAG = "mlflow.experimentKind"
"""MLflow's experiment tag naming what an experiment is for (its UI offers views by kind)."""
EXPERIMENT_KIND = "custom_model_development"
"""The kind of every experiment sray creates or logs into: model training (not ``genai_development``)."""


def default_tracking_uri(workdir: Path) -> str:
    """``sqlite:///<abs workdir>/mlflow.db``: the embedded default store of a working directory."""
    return f"sqlite:///{Path(workdir).resolve() / 'mlflow.db'}"


def sqlite_path(tracking_uri: str) -> Path | None:
    """The database file of a ``sqlite:///`` URI (absolute), or None for any other URI."""
    prefix = "sqlite:///"
    return Path(tracking_uri[len(prefix):]).resolve() if tracking_uri.startswith(prefix) else None


def is_server(tracking_uri: str) -> bool:
    """True for an ``http(s)://`` tracking server URI (which serves its own dashboard)."""
    return tracking_uri.startswith(("http://", "https://"))


def artifact_root(tracking_uri: str) -> Path | None:
    """``mlartifacts`` beside a SQLite database, where its artifacts go; None for any other store."""
    db = sqlite_path(tracking_uri)
    return None if db is None else db.parent / "mlartifacts"


def mlflow_client(tracking_uri: str) -> Any:
    """An ``MlflowClient`` for ``tracking_uri`` (also its model registry)."""
    from mlflow import MlflowClient

    return MlflowClient(tracking_uri=tracking_uri, registry_uri=tracking_uri)


def probe_server(tracking_uri: str, timeout_s: float = 3.0) -> None:
    """ConnectionError naming the URI unless ``/health`` answers within ``timeout_s`` (MLflow would retry minutes)."""
    try:
        with urllib.request.urlopen(f"{tracking_uri.rstrip('/')}/health", timeout=timeout_s):
            return
    except urllib.error.HTTPError as e:
        reason = f"HTTP {e.code}"
    except (urllib.error.URLError, OSError) as e:
        reason = str(getattr(e, "reason", e))
    raise ConnectionError(f"MLflow tracking server {tracking_uri} does not answer ({reason}); start it "
                          "(`sray cluster up` prints its URI) or fix --tracking-uri")


def ensure_store(tracking_uri: str) -> None:
    """Create the store's schema now, before workers start; ConnectionError naming the URI otherwise."""
    db = sqlite_path(tracking_uri)
    if is_server(tracking_uri):
        probe_server(tracking_uri)
    try:
        if db is not None:
            db.parent.mkdir(parents=True, exist_ok=True)
        mlflow_client(tracking_uri).search_experiments(max_results=1)
    except Exception as e:  # noqa: BLE001 - re-raised with the URI and the fix
        raise ConnectionError(f"MLflow tracking store {tracking_uri!r} is not usable ({e}); check --tracking-uri, or "
                              "leave it out to use the local SQLite store in the working directory") from e


def _experiment_id(client: Any, tracking_uri: str, experiment: str) -> str:
    """Id of ``experiment``, created (artifacts under :func:`artifact_root`) or restored, of :data:`EXPERIMENT_KIND`."""
    from mlflow.exceptions import MlflowException

    found = client.get_experiment_by_name(experiment)
    if found is None:
        root, folder = artifact_root(tracking_uri), re.sub(r"[^A-Za-z0-9._-]+", "_", experiment).strip("._")
        location = None if root is None else (root / (folder or "experiment")).as_uri()
        try:
            return client.create_experiment(experiment, artifact_location=location,
                                            tags={EXPERIMENT_KIND_TAG: EXPERIMENT_KIND})
        except MlflowException:
            found = client.get_experiment_by_name(experiment)  # created concurrently by another launcher
            if found is None:
                raise
    if found.lifecycle_stage == "deleted":
        client.restore_experiment(found.experiment_id)
        log.info("restored deleted MLflow experiment %r", experiment)
    if EXPERIMENT_KIND_TAG not in found.tags:
        client.set_experiment_tag(found.experiment_id, EXPERIMENT_KIND_TAG, EXPERIMENT_KIND)
    return found.experiment_id


def prepare_run(tracking_uri: str, experiment: str, run_name: str, tags: dict[str, str] | None = None,
                parent_run_id: str | None = None) -> RunHandle:
    """Create the schema, the experiment and a new RUNNING run (nested under ``parent_run_id``); return its handle."""
    ensure_store(tracking_uri)
    client = mlflow_client(tracking_uri)
    experiment_id = _experiment_id(client, tracking_uri, experiment)
    nest = {PARENT_RUN_TAG: parent_run_id} if parent_run_id else {}
    all_tags = {str(k): str(v) for k, v in (tags or {}).items()} | nest
    run = client.create_run(experiment_id, run_name=run_name, tags=all_tags)
    return run_handle(tracking_uri, experiment_id, run.info.run_id)


def run_handle(tracking_uri: str, experiment_id: str, run_id: str) -> RunHandle:
    """The handle of an existing run, with its page's address (and how to serve it for a local store)."""
    page = f"#/experiments/{experiment_id}/runs/{run_id}"
    if is_server(tracking_uri):
        url, hint = f"{tracking_uri.rstrip('/')}/{page}", ""
    else:
        url = f"http://127.0.0.1:{DEFAULT_UI_PORT}/{page}"
        hint = (f"sray ui --tracking-uri {tracking_uri}  (a lean MLflow server: --backend-store-uri {tracking_uri}, "
                f"one worker, no job runner, port {DEFAULT_UI_PORT})")
    return RunHandle(tracker=NAME, store=tracking_uri, run_id=run_id, experiment_id=experiment_id, ui_url=url,
                     ui_hint=hint)


def find_run(tracking_uri: str, experiment: str, run_name: str) -> RunHandle | None:
    """The newest run called ``run_name`` in ``experiment``, or None (no side effects)."""
    if "'" in run_name:
        raise ValueError(f"run name {run_name!r}: quotes are not allowed in run names")
    ensure_store(tracking_uri)
    client = mlflow_client(tracking_uri)
    found = client.get_experiment_by_name(experiment)
    if found is None:
        return None
    runs = client.search_runs([found.experiment_id], filter_string=f"attributes.run_name = '{run_name}'",
                              order_by=["attributes.start_time DESC"], max_results=1)
    return run_handle(tracking_uri, found.experiment_id, runs[0].info.run_id) if runs else None
