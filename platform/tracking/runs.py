"""MLflow runs prepared by the launcher, before any Ray worker starts.

The launcher (driver) creates the store schema, the experiment and the run once, then hands the
resulting :class:`RunHandle` (plain strings, picklable) to the workers. Rank 0 logs into that fixed
run id through :class:`sray.platform.tracking.logger.RunLogger`, so a worker group restarted by Ray
Train's ``FailureConfig`` keeps writing into the same run instead of opening a new one.

Default store (no ``--tracking-uri``): a SQLite file ``<workdir>/mlflow.db`` with artifacts under
``<workdir>/mlartifacts``. MLflow 3.17's file store raises, so the URI and artifact location are
always explicit. Several processes creating a new SQLite store at once corrupt it: the schema is
created here, in one process, before any fan-out.
"""

from __future__ import annotations

import logging
import re
from dataclasses import dataclass
from pathlib import Path

log = logging.getLogger(__name__)

DEFAULT_UI_PORT = 5000
"""Port the UI command suggested for a local store listens on."""

PARENT_RUN_TAG = "mlflow.parentRunId"
"""MLflow's tag that nests a run under a parent (fleet: one parent run, one child per scene)."""


@dataclass(frozen=True)
class RunHandle:
    """Everything a worker needs to log into a run prepared by the launcher (picklable strings)."""

    run_id: str
    """MLflow run id, fixed for the whole job (restarts included)."""
    experiment_id: str
    """Id of the run's experiment."""
    tracking_uri: str
    """Tracking URI the run lives in (``sqlite:///...`` or ``http(s)://...``)."""
    ui_url: str
    """Browser address of the run's page (for a local store: once the UI command runs)."""
    ui_hint: str = ""
    """For a local store: the command that starts the UI; empty for a tracking server."""


def default_tracking_uri(workdir: Path) -> str:
    """``sqlite:///<abs workdir>/mlflow.db``: the embedded default store of a working directory."""
    return f"sqlite:///{Path(workdir).resolve() / 'mlflow.db'}"


def default_artifact_root(workdir: Path) -> Path:
    """``<abs workdir>/mlartifacts``: where the default store keeps run artifacts."""
    return Path(workdir).resolve() / "mlartifacts"


def sqlite_path(tracking_uri: str) -> Path | None:
    """The database file of a ``sqlite:///`` URI (absolute), or None for any other URI."""
    prefix = "sqlite:///"
    if not tracking_uri.startswith(prefix):
        return None
    return Path(tracking_uri[len(prefix):]).resolve()


def _is_server(tracking_uri: str) -> bool:
    return tracking_uri.startswith(("http://", "https://"))


def _experiment_artifact_location(tracking_uri: str, experiment: str, artifact_root: Path | None) -> str | None:
    """Artifact location for a new experiment: ``<root>/<experiment as a safe folder name>`` (file URI).

    A tracking server decides for itself (``--artifacts-destination``), so None is returned there
    unless a root is given; a SQLite store without a root keeps artifacts beside the database.
    """
    if artifact_root is None:
        db = sqlite_path(tracking_uri)
        if db is None:
            return None
        artifact_root = db.parent / "mlartifacts"
    folder = re.sub(r"[^A-Za-z0-9._-]+", "_", experiment).strip("._") or "experiment"
    return (Path(artifact_root).resolve() / folder).as_uri()


def _ui_links(tracking_uri: str, experiment_id: str, run_id: str) -> tuple[str, str]:
    page = f"#/experiments/{experiment_id}/runs/{run_id}"
    if _is_server(tracking_uri):
        return f"{tracking_uri.rstrip('/')}/{page}", ""
    hint = (f"sray ui --tracking-uri {tracking_uri}  (a lean MLflow server: --backend-store-uri {tracking_uri}, "
            f"one worker, no job runner, port {DEFAULT_UI_PORT})")
    return f"http://127.0.0.1:{DEFAULT_UI_PORT}/{page}", hint


def _client(tracking_uri: str):
    from mlflow import MlflowClient

    return MlflowClient(tracking_uri=tracking_uri, registry_uri=tracking_uri)


def ensure_store(tracking_uri: str) -> None:
    """Create the store's schema now (for SQLite: the folder and tables), in this one process.

    Call before starting workers: concurrent first-time creation corrupts a SQLite store. Errors
    name the URI (an unreachable server, an unwritable folder).
    """
    db = sqlite_path(tracking_uri)
    try:
        if db is not None:
            db.parent.mkdir(parents=True, exist_ok=True)
        _client(tracking_uri).search_experiments(max_results=1)
    except Exception as e:  # noqa: BLE001 - re-raised with the URI and the fix
        raise ConnectionError(
            f"MLflow tracking store {tracking_uri!r} is not usable ({e}); check --tracking-uri, or "
            "leave it out to use the local SQLite store in the working directory") from e


def _experiment_id(client, tracking_uri: str, experiment: str, artifact_root: Path | None) -> str:
    """Id of ``experiment``, created (with an explicit artifact location) or restored if needed."""
    from mlflow.exceptions import MlflowException

    found = client.get_experiment_by_name(experiment)
    if found is None:
        location = _experiment_artifact_location(tracking_uri, experiment, artifact_root)
        try:
            return client.create_experiment(experiment, artifact_location=location)
        except MlflowException:
            found = client.get_experiment_by_name(experiment)  # created concurrently by another launcher
            if found is None:
                raise
    if found.lifecycle_stage == "deleted":
        client.restore_experiment(found.experiment_id)
        log.info("restored deleted MLflow experiment %r", experiment)
    return found.experiment_id


def prepare_run(tracking_uri: str, experiment: str, run_name: str, tags: dict[str, str] | None = None,
                parent_run_id: str | None = None, artifact_root: Path | None = None) -> RunHandle:
    """Create the schema (SQLite), the experiment and a new RUNNING run; return its fixed handle.

    ``artifact_root``: folder for a new experiment's artifacts (default: beside a SQLite database;
    a tracking server's own ``--artifacts-destination``). ``parent_run_id`` nests the run.
    """
    ensure_store(tracking_uri)
    client = _client(tracking_uri)
    experiment_id = _experiment_id(client, tracking_uri, experiment, artifact_root)
    all_tags = {str(k): str(v) for k, v in (tags or {}).items()}
    if parent_run_id:
        all_tags[PARENT_RUN_TAG] = parent_run_id
    run = client.create_run(experiment_id, run_name=run_name, tags=all_tags)
    return run_handle(tracking_uri, experiment_id, run.info.run_id)


def run_handle(tracking_uri: str, experiment_id: str, run_id: str) -> RunHandle:
    """The handle of an existing run (with its UI links)."""
    url, hint = _ui_links(tracking_uri, experiment_id, run_id)
    return RunHandle(run_id=run_id, experiment_id=experiment_id, tracking_uri=tracking_uri, ui_url=url, ui_hint=hint)


def find_run(tracking_uri: str, experiment: str, run_name: str) -> RunHandle | None:
    """The newest run called ``run_name`` in ``experiment``, or None (no side effects)."""
    if "'" in run_name:
        raise ValueError(f"run name {run_name!r}: quotes are not allowed in run names")
    ensure_store(tracking_uri)
    client = _client(tracking_uri)
    found = client.get_experiment_by_name(experiment)
    if found is None:
        return None
    runs = client.search_runs([found.experiment_id], filter_string=f"attributes.run_name = '{run_name}'",
                              order_by=["attributes.start_time DESC"], max_results=1)
    if not runs:
        return None
    return run_handle(tracking_uri, found.experiment_id, runs[0].info.run_id)


def resume_run(tracking_uri: str, experiment: str, run_name: str) -> RunHandle:
    """Find the run of a job being resumed and mark it RUNNING again; LookupError if there is none."""
    handle = find_run(tracking_uri, experiment, run_name)
    if handle is None:
        raise LookupError(f"no MLflow run named {run_name!r} in experiment {experiment!r} at {tracking_uri}; "
                          "check --name/--resume and --tracking-uri (they must match the original job)")
    _client(tracking_uri).update_run(handle.run_id, status="RUNNING")
    return handle


def terminate_run(handle: RunHandle, status: str) -> bool:
    """Mark a run FINISHED, FAILED or KILLED from the launcher; warns and returns False on failure."""
    try:
        _client(handle.tracking_uri).set_terminated(handle.run_id, status=status)
        return True
    except Exception as e:  # noqa: BLE001 - tracking problems never crash the job
        log.warning("could not mark MLflow run %s as %s at %s: %s", handle.run_id, status, handle.tracking_uri, e)
        return False
