"""``sray gpu-check``: the dry run exercises every stage on the CPU, a re-run resumes, a failing stage is a
result, a machine without CUDA is told so in one line, and the checkout's tests and docs are found from any folder."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
import torch

from sray.jobs.cli import main
from sray.jobs.gpu_check import context, runner, stage_training
from sray.jobs.gpu_check.report import REPORT_FILE, STAGE_NAMES, StageResult, load_report

REPO = Path(__file__).resolve().parents[1]


@pytest.mark.slow
def test_dry_run_runs_every_stage_and_a_rerun_resumes(ray_session, tmp_path: Path, capsys) -> None:
    assert main(["gpu-check", "--dry-run", "--out", str(tmp_path)]) == 0
    report = load_report(tmp_path)
    assert list(report["stages"]) == list(STAGE_NAMES)
    for name, result in report["stages"].items():
        assert result.status == "passed", (name, result.summary)
    precision = {(r[0], r[1]): r for r in report["stages"]["precision"].rows}
    assert set(precision) == {("bf16", c) for c in ("projection", "render argmax", "step loss", "step gradient")}
    assert all(r[-1] == "ok" for r in precision.values())
    assert [r[:2] for r in report["stages"]["training"].rows] == [["fp32", "32"], ["bf16", "32"], ["bf16", "128"]]
    assert [r[:2] for r in report["stages"]["recipe"].rows] == [
        [f"{p} {phase}", rays] for p, rays in (("fp32", "32"), ("bf16", "32"), ("bf16", "128"))
        for phase in ("2D warm-up", "ray steps")]
    curve = json.loads((tmp_path / "recipe_curve.json").read_text())["curves"]["bf16"]
    assert [p["phase"] for p in curve] == [0.0] * 3 + [1.0] * 3  # 3 warm-up steps render nothing, then ray steps
    assert curve[2]["sem_src"] < curve[0]["sem_src"] and curve[3]["loss"] > curve[3]["sem_src"]
    train, evaluation, render, refusal = report["stages"]["ray"].rows
    assert train[0] == "sray train, rank 0 killed at step 2, resumed" and train[2] == "4 steps"  # ran to its end
    assert evaluation[4].endswith("views/s") and render[2] == "4 frames" and render[0].startswith("sray render 80x60")
    assert "refuses two ranks on one GPU" in refusal[4]  # 2 workers, 0.5 GPU each
    alone, *shared = report["stages"]["fleet"].rows
    assert {"sray", "semantic-nerf", "2d-transfer"} <= {r[0].split(",")[0] for r in shared}
    assert alone[1] == "1" and all(r[1] == "2" and float(r[5]) > 0 for r in shared)  # 2 scenes in a dry run
    assert report["stages"]["minutes"].rows[0][:2] == ["synth-gpu-minutes", "4"]
    profiled = {r[0] for r in report["stages"]["profile"].rows}
    assert profiled == {"training step, impl=fast", "training step, impl=fast, bf16", "whole-image render, impl=fast"}
    renders = [r[1] for r in report["stages"]["bench"].rows if r[0] == "whole-view render"]
    assert [r.split(": ")[0].rsplit(", ", 1)[1] for r in renders] == ["fp32", "bf16"]
    text = (tmp_path / "gpu_check.md").read_text()
    for name in STAGE_NAMES:
        assert f"\n{name} | passed |" in text
    capsys.readouterr()
    # a re-run skips every stage already in the report (and changes none of them)
    before = (tmp_path / REPORT_FILE).read_text()
    assert main(["gpu-check", "--dry-run", "--out", str(tmp_path), "--stages", "environment", "precision"]) == 0
    printed = capsys.readouterr().out
    assert printed.count("already in the report") == 2
    assert (tmp_path / REPORT_FILE).read_text() == before


def test_recipe_stage_fails_when_the_warm_up_does_not_learn(tmp_path: Path, monkeypatch) -> None:
    flat = [{"phase": float(i >= 3), "seconds": 0.1, "loss": 3.0, "sem_src": 3.0, "skipped": 0.0} for i in range(6)]
    monkeypatch.setattr(stage_training, "phase_curve", lambda ctx, precision, steps, rays: flat)
    ctx = context.CheckContext(torch.device("cpu"), True, tmp_path, REPO)
    result = stage_training.recipe(ctx)
    assert result.status == "failed" and "did not fall over the warm-up" in result.summary


def test_brightness_labels_cut_the_mean_channel_into_bands() -> None:
    rgb = torch.tensor([0.0, 0.049, 0.05, 0.5, 0.999, 1.0]).view(1, 1, 1, 6).expand(1, 3, 1, 6)
    assert stage_training.brightness_labels(rgb, 20).flatten().tolist() == [0, 0, 1, 10, 19, 19]


def test_a_failing_stage_is_recorded_and_the_next_stage_runs(tmp_path: Path, monkeypatch) -> None:
    def broken(ctx: object) -> StageResult:
        raise FloatingPointError("NaN in the bf16 render")

    monkeypatch.setitem(runner.STAGES, "precision", broken)
    report = runner.run_gpu_check(["precision", "environment"], tmp_path, dry_run=True, fresh=False, repo=REPO,
                                  doc=None)
    assert report["stages"]["precision"].status == "failed"
    assert "FloatingPointError: NaN in the bf16 render" in report["stages"]["precision"].summary
    assert (tmp_path / "precision.error.log").exists()
    assert report["stages"]["environment"].status == "passed"
    assert main(["gpu-check", "--dry-run", "--out", str(tmp_path), "--stages", "precision"]) == 1


def test_without_cuda_it_says_so_in_one_line_and_fails(tmp_path: Path, capsys) -> None:
    import torch

    if torch.cuda.is_available():
        pytest.skip("this machine has CUDA")
    assert main(["gpu-check", "--out", str(tmp_path)]) == 2
    out = capsys.readouterr().out.strip().splitlines()
    assert len(out) == 1 and "no CUDA device" in out[0] and "--dry-run" in out[0]
    assert not (tmp_path / REPORT_FILE).exists()


def test_from_another_folder_the_tests_stage_runs_the_checkouts_tests(tmp_path: Path, monkeypatch) -> None:
    monkeypatch.chdir(tmp_path)
    assert main(["gpu-check", "--dry-run", "--out", "out", "--stages", "tests"]) == 0
    result = load_report(tmp_path / "out")["stages"]["tests"]
    assert result.status == "passed", result.summary
    assert "passed" in result.summary and "skipped" in result.summary  # the quick model test; the gpu tests skip
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]  # nothing but --out, which stays relative


def test_from_another_folder_the_report_goes_to_the_checkouts_docs(tmp_path: Path, monkeypatch) -> None:
    seen = {}

    def fake_run(stages: list[str], out: Path, dry_run: bool, fresh: bool, repo: Path, doc: Path | None) -> dict:
        seen.update(repo=repo, doc=doc)
        return {"device": None, "stages": {}}

    monkeypatch.setattr(runner, "run_gpu_check", fake_run)
    monkeypatch.chdir(tmp_path)
    assert main(["gpu-check", "--out", "out"]) == 0
    assert seen == {"repo": REPO, "doc": REPO / "docs" / "benchmarks.md"}
    assert main(["gpu-check", "--out", "out", "--doc", "mine.md"]) == 0
    assert seen["doc"] == Path("mine.md")  # a path the user names stays relative to the working directory


def test_an_installation_without_the_checkout_is_refused_in_one_line(tmp_path: Path, monkeypatch, capsys) -> None:
    wheel = tmp_path / "site-packages" / "sray"
    (wheel / "jobs").mkdir(parents=True)
    monkeypatch.setattr(context, "INSTALLED_AT", wheel)
    monkeypatch.chdir(tmp_path)
    assert main(["gpu-check", "--dry-run", "--out", "out"]) == 2
    out = capsys.readouterr().out.strip().splitlines()
    assert len(out) == 1 and str(wheel) in out[0] and "tests/ or docs/" in out[0] and "pip install -e ." in out[0]
    assert not (tmp_path / "out").exists()


def test_table_cells_reads_header_and_rows_and_skips_the_separator() -> None:
    from sray.jobs.gpu_check.report import table_cells

    table = "| op | calls | ms |\n|---|---:|:---:|\n| `mm` | 4 | 1.5 |\n| `add` | 2 | - |\n\nWall time: 3 s"
    assert table_cells(table) == (["op", "calls", "ms"], [["`mm`", "4", "1.5"], ["`add`", "2", "-"]])
