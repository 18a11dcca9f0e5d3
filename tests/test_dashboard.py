"""``sray ui``: the lean MLflow dashboard on a store holding a finished fleet, loaded in headless Chromium.

The store is built here: a parent fleet run, two child runs (``mlflow.parentRunId``) with metrics,
and the fleet's charts (from :mod:`sray.platform.viz.charts`) as artifacts of the parent. Chromium is
Debian's package, installed by the fixture when missing and we are root; otherwise the browser tests
skip and say why. The browser tests use a fresh profile per page: what a new user sees.
"""

from __future__ import annotations

import ast
import html
import os
import re
import shutil
import socket
import subprocess
import sys
import urllib.request
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))
from mlflow_fixtures import mlflow_template, mlflow_uri  # noqa: E402,F401  (pytest fixtures, used by name)
from test_charts import synthetic_result  # noqa: E402

from sray.platform.tracking.dashboard import runs_view_url, start_dashboard  # noqa: E402
from sray.platform.tracking.runs import EXPERIMENT_KIND, EXPERIMENT_KIND_TAG, mlflow_client  # noqa: E402

CHROMIUM_FLAGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
                  "--disable-component-update", "--disable-sync", "--no-first-run", "--disable-quic",
                  "--virtual-time-budget=20000", "--window-size=1400,900"]
CHART = "charts/miou_vs_step.png"
INSTALL_TIMEOUT_S = 900
REPO = Path(__file__).resolve().parents[1]
GENAI_MARKERS = ("Overview", "Observability", "Judges", "Agent versions", "Detect Issues", "AI Gateway", "Start Demo",
                 "Getting Started", "MCP registry", "Ask questions about your", "Information about UI telemetry")
"""Texts of MLflow 3.17's GenAI view (experiment tabs, home page cards), its open assistant panel and its
UI-telemetry notice, none of which its model-training view shows (DOMs of both compared by hand)."""
SCENES = ("scene_alpha", "scene_beta")
CHILD_METRICS = {"result/miou_before": 0.45, "result/miou_after": 0.61, "result/psnr_after": 21.5,
                 "result/artifact_bytes": 123456.0}


def _install_chromium() -> str | None:
    """Path of a chromium binary, installing Debian's package when missing (root only); None if impossible."""
    found = shutil.which("chromium") or shutil.which("chromium-browser")
    if found or os.geteuid() != 0 or shutil.which("apt-get") is None:
        return found
    env = {**os.environ, "DEBIAN_FRONTEND": "noninteractive"}
    for cmd in (["apt-get", "install", "-y", "-q", "chromium"], ["apt-get", "update", "-q"],
                ["apt-get", "install", "-y", "-q", "chromium"]):
        try:
            subprocess.run(cmd, env=env, capture_output=True, timeout=INSTALL_TIMEOUT_S, check=False)
        except subprocess.TimeoutExpired:
            return None
        if shutil.which("chromium"):
            return shutil.which("chromium")
    return None


@pytest.fixture(scope="module")
def chromium() -> str:
    """The chromium executable (skips the test with the reason when there is none)."""
    path = _install_chromium()
    if path is None:
        reason = ("not root, cannot apt-get install chromium" if os.geteuid() != 0 else
                  "apt-get install chromium failed or timed out (no package registry reachable?)")
        pytest.skip(f"headless Chromium unavailable: {reason}")
    probe = subprocess.run([path, "--version"], capture_output=True, text=True, timeout=60, check=False)
    if probe.returncode != 0:
        pytest.skip(f"{path} does not start here: {(probe.stderr or probe.stdout).strip()[:300]}")
    return path


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _browser(chromium: str, url: str, profile: Path, screenshot: Path | None = None) -> str:
    """The page's DOM after its scripts ran (and a screenshot if asked)."""
    args = [chromium, *CHROMIUM_FLAGS, f"--user-data-dir={profile}"]
    if screenshot is not None:
        subprocess.run([*args, f"--screenshot={screenshot}", url], capture_output=True, timeout=120, check=False)
    done = subprocess.run([*args, "--dump-dom", url], capture_output=True, text=True, timeout=120, check=False)
    return done.stdout


def _finished_fleet(uri: str, tmp_path: Path) -> dict:
    """A parent fleet run (the fleet's own naming, folder ``demo/fleet``) with two finished child runs named
    as the fleet names them, and the fleet's charts as parent artifacts."""
    from sray.platform.finetune.fleet import parent_run
    from sray.platform.finetune.methods.registry import METHODS
    from sray.platform.tracking.mlflow_tracker import MlflowTracker
    from sray.platform.viz.charts import write_fleet_charts

    tracker = MlflowTracker(uri)
    new_record = {"tracker": tracker.name, "tracking_uri": tracker.store, "parent_run_id": None}
    parent, _ = parent_run(tracker, new_record, "sray-fleet", tmp_path / "demo" / "fleet")
    children, results = [], []
    for scene in SCENES:
        child = tracker.start_run("sray-fleet", f"{scene} · sray", parent=parent)
        with tracker.logger(child) as logger:
            logger.log_metrics({"heldout/miou": 0.45} | CHILD_METRICS, 40)
        children.append(child)
        results.append(synthetic_result(scene, "sray", 4))
    charts = write_fleet_charts(results, tmp_path / "charts", METHODS)
    with tracker.logger(parent) as logger:
        logger.log_metrics({"sray/miou_after_mean": 0.61}, 0)
        for chart in charts:
            logger.log_artifact(chart, "charts")
    return {"parent": parent, "children": children, "chart": tmp_path / CHART}


def run_artifacts_url(base_url: str, experiment_id: str, run_id: str, path: str) -> str:
    """Address of a run's artifacts tab with the artifact at ``path`` selected and previewed."""
    return f"{base_url}/#/experiments/{experiment_id}/runs/{run_id}/artifacts/{path}?workflowType=machine_learning"


def _visible_text(dom: str) -> str:
    """The text a page shows: its DOM without scripts, styles and tags."""
    dom = re.sub(r"<(script|style)\b.*?</\1>", " ", dom, flags=re.S)
    return html.unescape(re.sub(r"<[^>]+>", "\n", dom))


@pytest.mark.slow
def test_dashboard_shows_the_fleet_and_its_chart_in_chromium(chromium, mlflow_uri, tmp_path):
    fleet = _finished_fleet(mlflow_uri, tmp_path)
    parent, exp = fleet["parent"], fleet["parent"].experiment_id
    with start_dashboard(mlflow_uri, port=_free_port()) as ui:
        assert ui.base_url.startswith("http://127.0.0.1:")
        assert ui.url == runs_view_url(ui.base_url, exp) and "workflowType=machine_learning" in ui.url
        assert list(ui.experiment_urls) == ["sray-fleet"]
        # the server serves the parent's artifact (logged to a file:// location) byte for byte
        with urllib.request.urlopen(f"{ui.base_url}/get-artifact?path={CHART}&run_uuid={parent.run_id}") as reply:
            assert reply.read() == fleet["chart"].read_bytes()

        runs_dom = _browser(chromium, runs_view_url(ui.base_url, exp, flat=True), tmp_path / "profile-runs",
                            tmp_path / "runs.png")
        for name in ["fleet · demo/fleet", "scene_alpha · sray", "scene_beta · sray"]:
            assert name in runs_dom, f"run {name!r} is not in the runs page (screenshot: {tmp_path / 'runs.png'})"

        art_dom = _browser(chromium, run_artifacts_url(ui.base_url, exp, parent.run_id, CHART),
                           tmp_path / "profile-art", tmp_path / "artifacts.png")
        assert "fleet · demo/fleet" in art_dom and CHART in art_dom
        # the preview <img> holds the bytes the UI fetched from the server (a blob: URL)
        assert f'alt="{CHART}" src="blob:' in art_dom, "the chart preview did not load in the artifacts page"
        process = ui.process
    assert process.poll() is not None  # stopped with the with-block, worker included: nobody answers
    with pytest.raises(OSError):
        urllib.request.urlopen(f"{ui.base_url}/health", timeout=5)


@pytest.mark.slow
def test_dashboard_opens_on_training_runs_without_query_parameters(chromium, mlflow_uri, tmp_path):
    """The bare server address and ``#/experiments/<id>``, each in a new browser: MLflow's model-training view
    with the fleet unfolded (its scene runs under it) and the headline metric columns; no GenAI view, assistant
    panel or telemetry notice."""
    fleet = _finished_fleet(mlflow_uri, tmp_path)
    exp = fleet["parent"].experiment_id
    assert mlflow_client(mlflow_uri).get_experiment(exp).tags[EXPERIMENT_KIND_TAG] == EXPERIMENT_KIND
    with start_dashboard(mlflow_uri, port=_free_port()) as ui:
        for page, url in [("root", f"{ui.base_url}/"), ("experiment", f"{ui.base_url}/#/experiments/{exp}")]:
            dom = _browser(chromium, url, tmp_path / f"profile-{page}")
            text = _visible_text(dom)
            assert "Model training" in text and "Runs" in text, f"{page}: the page did not load:\n{text[:2000]}"
            shown = [marker for marker in GENAI_MARKERS if marker in text]
            assert not shown, f"{page} ({url}) shows MLflow's GenAI view: {shown}"
            for name in ["fleet · demo/fleet", "scene_alpha · sray", "scene_beta · sray"]:
                assert name in text, f"{page}: run {name!r} is not listed (the fleet is folded?)"
            for key in CHILD_METRICS:
                assert f'col-id="metrics.`{key}`"' in dom, f"{page}: no column for the headline metric {key}"
            assert "123456" in text and "21.5" in text, f"{page}: the scene runs' metric values are not shown"


def test_every_experiment_sray_makes_is_a_model_training_experiment(mlflow_uri):
    """The tracker tags each experiment it creates with MLflow's training kind, and an existing one without a
    kind when it logs into it; a kind chosen by someone else stays; no other module creates experiments."""
    from sray.platform.tracking.mlflow_tracker import MlflowTracker

    client, tracker = mlflow_client(mlflow_uri), MlflowTracker(mlflow_uri)
    parent = tracker.start_run("sray-fleet", "fleet · demo/fleet")
    tracker.start_run("sray-fleet", "scene · sray", parent=parent)
    tracker.start_run("sray-eval", "eval-job-step_100")
    client.create_experiment("made-elsewhere")
    client.create_experiment("chosen-kind", tags={EXPERIMENT_KIND_TAG: "genai_development"})
    tracker.start_run("made-elsewhere", "train-job")
    tracker.start_run("chosen-kind", "train-job")
    kinds = {e.name: e.tags.get(EXPERIMENT_KIND_TAG) for e in client.search_experiments()}
    assert kinds == {"Default": None, "sray-fleet": EXPERIMENT_KIND, "sray-eval": EXPERIMENT_KIND,
                     "made-elsewhere": EXPERIMENT_KIND, "chosen-kind": "genai_development"}
    assert tracker.find_run("absent", "x") is None and client.get_experiment_by_name("absent") is None
    makers = [str(path.relative_to(REPO)) for folder in ("platform", "jobs", "model", "data_tools")
              for path in sorted((REPO / folder).rglob("*.py"))
              if any(isinstance(node, ast.Attribute) and node.attr in ("create_experiment", "set_experiment")
                     for node in ast.walk(ast.parse(path.read_text())))]
    assert makers == ["platform/tracking/runs.py"]


def test_landing_page_unfolds_parents_and_shows_headline_columns(mlflow_uri, tmp_path):
    """What the landing page's script applies: per sray experiment its table-state key, the headline columns
    and the parent runs; the bare address goes to the experiment with the newest run."""
    from sray.platform.tracking.ui_app import HEADLINE_METRICS, landing_config, metric_column

    fleet = _finished_fleet(mlflow_uri, tmp_path)
    client = mlflow_client(mlflow_uri)
    client.create_experiment("not-ours")
    config = landing_config(client)
    exp = fleet["parent"].experiment_id
    assert config["start"] == f"#/experiments/{exp}"
    assert config["experiments"] == [{"key": f'MLflowLocalStorage-1.1-ExperimentPage-["{exp}"]-ReactComponentState',
                                      "columns": [metric_column(m) for m in HEADLINE_METRICS],
                                      "parents": [fleet["parent"].run_id]}]
    assert set(CHILD_METRICS) <= set(HEADLINE_METRICS)
    assert config["defaults"]["mlflow.workflowType_v1"] == "machine_learning"


def test_ui_refuses_what_it_cannot_serve(tmp_path, mlflow_uri, capsys):
    from sray.jobs.cli import main

    assert main(["ui", "--tracking-uri", f"sqlite:///{tmp_path / 'absent' / 'mlflow.db'}"]) == 2
    assert "no MLflow store there" in capsys.readouterr().err
    assert main(["ui", "--tracking-uri", "http://127.0.0.1:9"]) == 2
    assert "does not answer" in capsys.readouterr().err
    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        assert main(["ui", "--tracking-uri", mlflow_uri, "--port", str(busy.getsockname()[1])]) == 2
        assert "pass --port with a free port" in capsys.readouterr().err
