"""The fleet's parent run, seen from the driver: reuse the recorded one or start one.

Works with any :class:`~sray.platform.tracking.tracker.Tracker`. Tracking problems only warn: they
never stop a fleet.
"""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Any

from sray.platform.tracking.tracker import RunHandle, Tracker

log = logging.getLogger(__name__)


def parent_run(tracker: Tracker, record: dict[str, Any], experiment: str, out_dir: Path) -> tuple[RunHandle, bool]:
    """The parent run: the one ``record`` names (marked RUNNING again) if it still exists in this
    tracker's store, else a new one named ``fleet · <folder's parent>/<folder>``. Returns (handle, whether
    it is new).

    ``record``: the fleet's ``fleet.json`` (``parent_run_id``, ``tracker`` and ``tracking_uri`` = the store).
    """
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
