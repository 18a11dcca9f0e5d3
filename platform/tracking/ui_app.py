"""``sray ui``'s server app: MLflow's landing page with a script presetting its ``localStorage`` (docs/dashboard.md)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from flask import Response
from mlflow.entities import ViewType
from mlflow.server import app as flask_app
from mlflow.server.fastapi_app import app
from mlflow.server.handlers import _get_tracking_store

from sray.platform.tracking.runs import EXPERIMENT_KIND, EXPERIMENT_KIND_TAG, PARENT_RUN_TAG

UI_DEFAULTS: dict[str, object] = {"mlflow.workflowType_v1": "machine_learning",
                                  "mlflow.assistant.fab.autoOpenedOnFirstLoad_v1": True,
                                  "mlflow.telemetry.info.alert.dismissed_v1": True}
"""The model-training view, no assistant panel opening by itself, no UI-telemetry notice (telemetry is off)."""
HEADLINE_METRICS = ("result/miou_before", "result/miou_after", "result/psnr_after", "result/artifact_bytes",
                    "mean/miou", "mean/psnr", "zeroshot/miou", "zeroshot/psnr")
"""Metric columns of a runs table: a fleet's scene runs, an evaluation, a training run."""
RUNS_TABLE_STATE = "MLflowLocalStorage-1.1-ExperimentPage-{}-ReactComponentState"
"""MLflow's ``localStorage`` key of an experiment's runs-table state ({} = the JSON list of its id)."""
UNFOLDED_KEY = "sray.unfoldedParents"
"""``localStorage`` key of the parent runs this app has unfolded once (never again: the user may fold them)."""
MAX_RUNS = 1000
LANDING_PAGE = Path(flask_app.static_folder) / "index.html"
SCRIPT = """<script>(function(c){
var s=window.localStorage,k,i,j;
try{
for(k in c.defaults){if(s.getItem(k)===null){s.setItem(k,JSON.stringify(c.defaults[k]));}}
var done=JSON.parse(s.getItem(c.unfoldedKey)||"[]");
for(i=0;i<c.experiments.length;i++){
var e=c.experiments[i],saved=s.getItem(e.key);
var state=saved?JSON.parse(saved):{selectedColumns:e.columns};
state.runsExpanded=state.runsExpanded||{};
for(j=0;j<e.parents.length;j++){var p=e.parents[j];
if(done.indexOf(p)<0){state.runsExpanded[p]=true;done.push(p);}}
s.setItem(e.key,JSON.stringify(state));}
s.setItem(c.unfoldedKey,JSON.stringify(done));
}catch(x){}
if(c.start&&!window.location.hash){window.history.replaceState(null,"",c.start);}
})(%s);</script>"""
"""The landing page's first script; its argument is :func:`landing_config`."""


def metric_column(key: str) -> str:
    """MLflow's runs-table column id of metric ``key``."""
    return f"metrics.`{key}`"


def landing_config(store: Any) -> dict[str, Any]:
    """The landing script's argument, read from the tracking ``store``."""
    experiments, newest = [], (0, "#/experiments")
    kind = f"tags.`{EXPERIMENT_KIND_TAG}` = '{EXPERIMENT_KIND}'"
    for exp in store.search_experiments(view_type=ViewType.ACTIVE_ONLY, filter_string=kind, max_results=1000):
        last = store.search_runs([exp.experiment_id], None, ViewType.ACTIVE_ONLY, max_results=1,
                                 order_by=["attributes.start_time DESC"])
        if not last:
            continue
        newest = max(newest, (int(last[0].info.start_time or 0), f"#/experiments/{exp.experiment_id}"))
        children = store.search_runs([exp.experiment_id], f"tags.`{PARENT_RUN_TAG}` LIKE '%'", ViewType.ACTIVE_ONLY,
                                     max_results=MAX_RUNS)
        experiments.append({"key": RUNS_TABLE_STATE.format(json.dumps([exp.experiment_id])),
                            "columns": [metric_column(m) for m in HEADLINE_METRICS],
                            "parents": sorted({run.data.tags[PARENT_RUN_TAG] for run in children})})
    return {"defaults": UI_DEFAULTS, "unfoldedKey": UNFOLDED_KEY, "experiments": experiments, "start": newest[1]}


def landing_page() -> Response:
    """MLflow's ``index.html`` with :data:`SCRIPT` first in its ``<head>`` (not cached: it follows the store)."""
    script = SCRIPT % json.dumps(landing_config(_get_tracking_store()))
    html = LANDING_PAGE.read_text(encoding="utf-8").replace("<head>", "<head>" + script, 1)
    return Response(html, mimetype="text/html", headers={"Cache-Control": "no-cache"})


flask_app.view_functions["serve"] = landing_page
