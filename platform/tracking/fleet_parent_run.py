"""The fleet's parent MLflow run, seen from the driver: reuse the recorded one or start one; tag it.

Tracking problems only warn: they never stop a fleet.
"""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Any

from sray.platform.tracking.runs import RunHandle, prepare_run, run_handle

log = logging.getLogger(__name__)


def parent_run(record: dict[str, Any], tracking_uri: str, experiment: str, out_dir: Path) -> tuple[RunHandle, bool]:
    """The parent run: the recorded one (marked RUNNING again) if it still exists there, else a new one."""
    from mlflow import MlflowClient

    if record.get("parent_run_id") and record.get("tracking_uri") == tracking_uri:
        client = MlflowClient(tracking_uri=tracking_uri)
        try:
            run = client.get_run(record["parent_run_id"])
            client.update_run(run.info.run_id, status="RUNNING")
            return run_handle(tracking_uri, run.info.experiment_id, run.info.run_id), False
        except Exception as e:  # noqa: BLE001 - deleted or unreachable: start a new parent
            log.warning("parent run %s not usable (%s); starting a new one", record["parent_run_id"], e)
    handle = prepare_run(tracking_uri, experiment, f"fleet:{out_dir.name}",
                         tags={"sray.kind": "fleet", "sray.fleet_dir": str(out_dir)})
    return handle, True


def tag_run(handle: RunHandle, tags: dict[str, str]) -> None:
    """Set tags on a run from the driver; tracking problems only warn."""
    from mlflow import MlflowClient

    try:
        client = MlflowClient(tracking_uri=handle.tracking_uri)
        for key, value in tags.items():
            client.set_tag(handle.run_id, key, value[:5000])
    except Exception as e:  # noqa: BLE001 - tracking never stops the fleet
        log.warning("could not tag MLflow run %s: %s", handle.run_id, e)
