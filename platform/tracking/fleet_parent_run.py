"""The fleet's parent run, seen from the driver: reuse the recorded one or start one (problems only warn)."""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Any

from sray.platform.tracking.tracker import RunHandle, Tracker

log = logging.getLogger(__name__)


def parent_run(tracker: Tracker, record: dict[str, Any], experiment: str, out_dir: Path) -> tuple[RunHandle, bool]:
    """(handle, whether new) of the parent run: the one the fleet's ``fleet.json`` ``record`` names (marked RUNNING
    again) if this tracker's store still has it, else a new one named ``fleet · <folder's parent>/<folder>``."""
    same_store = record["tracker"] == tracker.name and record["tracking_uri"] == tracker.store
    if record.get("parent_run_id") and same_store:
        try:
            handle = tracker.get_run(record["parent_run_id"])
            tracker.set_status(handle, "RUNNING")
            return handle, False
        except Exception as e:  # noqa: BLE001 - deleted or unreachable: start a new parent
            log.warning("parent run %s not usable (%s); starting a new one", record["parent_run_id"], e)
    handle = tracker.start_run(experiment, f"fleet · {out_dir.parent.name}/{out_dir.name}",
                               tags={"sray.kind": "fleet", "sray.fleet_dir": str(out_dir)})
    return handle, True
