"""``sray ui``: the lean MLflow dashboard on a store holding a finished fleet, loaded in headless Chromium.

The store is built here: a parent fleet run, two child runs (``mlflow.parentRunId``) with metrics,
and the fleet's charts (from :mod:`sray.platform.viz.charts`) as artifacts of the parent. Chromium is
Debian's package, installed by the fixture when missing and we are root; otherwise the browser test
skips and says why.
"""

from __future__ import annotations

import os
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

from sray.platform.tracking.dashboard import run_artifacts_url, runs_view_url, start_dashboard  # noqa: E402

CHROMIUM_FLAGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
                  "--disable-component-update", "--disable-sync", "--no-first-run", "--disable-quic",
                  "--virtual-time-budget=20000", "--window-size=1400,900"]
CHART = "charts/miou_vs_step.png"
INSTALL_TIMEOUT_S = 900


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
    """A parent fleet run with two finished child runs and the fleet's charts as parent artifacts."""
    from sray.platform.finetune.methods.registry import METHODS
    from sray.platform.tracking.mlflow_tracker import MlflowTracker
    from sray.platform.viz.charts import write_fleet_charts

    tracker = MlflowTracker(uri)
    parent = tracker.start_run("sray-fleet", "fleet-ui-test", tags={"sray.kind": "fleet"})
    children, results = [], []
    for scene in ("scene_alpha", "scene_beta"):
        child = tracker.start_run("sray-fleet", f"{scene}-sray", parent=parent)
        with tracker.logger(child) as logger:
            logger.log_metrics({"heldout/miou": 0.45, "result/miou_after": 0.61}, 40)
        children.append(child)
        results.append(synthetic_result(scene, "sray", 4))
    charts = write_fleet_charts(results, tmp_path / "charts", METHODS)
    with tracker.logger(parent) as logger:
        logger.log_metrics({"fleet/miou_after_mean": 0.61}, 0)
        for chart in charts:
            logger.log_artifact(chart, "charts")
    return {"parent": parent, "children": children, "chart": tmp_path / CHART}


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
        for name in ["fleet-ui-test", "scene_alpha-sray", "scene_beta-sray"]:
            assert name in runs_dom, f"run {name!r} is not in the runs page (screenshot: {tmp_path / 'runs.png'})"

        art_dom = _browser(chromium, run_artifacts_url(ui.base_url, exp, parent.run_id, CHART),
                           tmp_path / "profile-art", tmp_path / "artifacts.png")
        assert "fleet-ui-test" in art_dom and CHART in art_dom
        # the preview <img> holds the bytes the UI fetched from the server (a blob: URL)
        assert f'alt="{CHART}" src="blob:' in art_dom, "the chart preview did not load in the artifacts page"
        process = ui.process
    assert process.poll() is not None  # stopped with the with-block, worker included: nobody answers
    with pytest.raises(OSError):
        urllib.request.urlopen(f"{ui.base_url}/health", timeout=5)


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
