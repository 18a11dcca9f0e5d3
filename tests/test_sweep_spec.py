"""``sray sweep`` without Ray: the spec grammar, the plan, the trial wrapper, outcomes, table and chart, and
bad specs refused in one line with exit code 2 before anything is written."""

from __future__ import annotations

import dataclasses
import math
import time
from pathlib import Path

import pytest
from engine_here import run_study_here
from injected_faults import injected_faults

from sray.jobs.cli import main
from sray.platform.common.fault_hook import InjectedFailure
from sray.platform.config.recipes import get_recipe
from sray.platform.sweep.prepare import plan_concurrency
from sray.platform.sweep.engine import _run_trial, _TrialJob
from sray.platform.sweep.outcomes import collect_outcomes, write_tables
from sray.platform.sweep.spec import SpecError, build_plan, parse_assignment, parse_param, with_seeds
from sray.platform.sweep.study import (BY_BUDGET, BY_SCHEDULER, TrialContext, append_history, read_record,
                                       request_stop, trial_folder)
from sray.platform.train.resources import InfeasibleRequest, NodeResources
from sray.platform.viz.sweep_chart import TrialCurve, write_sweep_chart


def test_distributions_parse_and_draw_in_range() -> None:
    """Every distribution parses; draws stay in their ranges; a grid is crossed with each sample."""
    params = [parse_param("optim.lr", "loguniform(1e-4, 1e-2)"), parse_param("model.lambda_rgb", "uniform(0.5,1)"),
              parse_param("model.attention", "choice(full, cross)"), parse_param("run.workers", "grid(1, 2)")]
    plan = build_plan(with_seeds(params, 3), samples=4, seed=7)
    assert len(plan) == 4 * 2 * 3 and list(plan)[:2] == ["t000", "t001"]
    for point in plan.values():
        assert 1e-4 <= point["optim.lr"] <= 1e-2 and 0.5 <= point["model.lambda_rgb"] <= 1.0
        assert point["model.attention"] in ("full", "cross") and point["run.workers"] in ("1", "2")
    assert {p["run.seed"] for p in plan.values()} == {"0", "1", "2"}
    assert build_plan(params, samples=4, seed=7) == build_plan(params, samples=4, seed=7)
    logs = sorted(math.log10(p["optim.lr"]) for p in build_plan(params[:1], samples=200, seed=0).values())
    assert logs[0] < -3.5 and logs[-1] > -2.5, "loguniform spreads over the decades"


def test_a_finished_trial_never_runs_again_and_an_errored_one_stays_errored(tmp_path: Path) -> None:
    """The engine's trial wrapper: one launch records the outcome; later launches run nothing."""
    calls: list[str] = []

    def point_fn(point: dict, ctx: TrialContext) -> None:
        calls.append(ctx.key)

    job = _TrialJob(point_fn, {"t000": {"a.b": 1}, "t001": {"a.b": 2}, "t002": {"a.b": 3}}, str(tmp_path), {})
    _run_trial({"key": "t000"}, job)
    _run_trial({"key": "t000"}, job)
    assert calls == ["t000"] and read_record(trial_folder(tmp_path, "t000")).outcome == "finished"
    with injected_faults("sweep.fail_trials=t001"):
        with pytest.raises(InjectedFailure):
            _run_trial({"key": "t001"}, job)
    with pytest.raises(RuntimeError, match="errored in an earlier launch"):
        _run_trial({"key": "t001"}, job)
    request_stop(trial_folder(tmp_path, "t002"), BY_SCHEDULER, 4)
    _run_trial({"key": "t002"}, job)
    assert calls == ["t000"], "neither the errored trial nor the stopped one ran again"


def test_a_study_run_piece_by_piece_keeps_results_and_reruns_only_errors(tmp_path: Path, monkeypatch) -> None:
    """The harnesses' way of running the engine (``run_missing``), with Tune replaced by the trial wrapper run
    in this process: results kept in the records, a finished trial never computed again, an errored trial run
    again by the next launch, no trial started past the time limit."""
    from sray.platform.sweep import engine
    from sray.platform.sweep.study import FINISHED, StudySettings, TrialRecord, write_record

    monkeypatch.setattr(engine, "run_study", run_study_here)
    calls: list[str] = []

    def square(point: dict, ctx: TrialContext) -> dict:
        calls.append(ctx.key)
        return {"y": point["x"] ** 2}

    plan = {k: {"x": x} for k, x in (("a", 2), ("b", 3), ("c", 4), ("d", 5))}
    settings = StudySettings(folder=tmp_path, metric="y", mode="max", label="test")
    write_record(trial_folder(tmp_path, "c"), TrialRecord(outcome=FINISHED, result={"y": -1}))
    with injected_faults("sweep.fail_trials=b"):
        first = engine.run_missing(plan, square, settings)
    assert [(o.key, o.reason, o.result) for o in first] == [
        ("a", "finished", {"y": 4}), ("b", "errored", None), ("c", "finished", {"y": -1}), ("d", "finished", {"y": 25})]
    assert calls == ["a", "d"]
    assert engine.missing(tmp_path, plan) == {"b": {"x": 3}}
    late = dataclasses.replace(settings, start_by=time.time() - 1)
    assert [o.reason for o in engine.run_missing(plan, square, late)][1] == "errored" and len(calls) == 2
    job = _TrialJob(square, plan, str(tmp_path), {}, time.time() - 1)  # the trial wrapper's own gate
    _run_trial({"key": "e"}, dataclasses.replace(job, plan={**plan, "e": {"x": 1}}))
    assert read_record(trial_folder(tmp_path, "e")).launches == [] and len(calls) == 2
    second = engine.run_missing(plan, square, settings)
    assert calls == ["a", "d", "b"] and [o.reason for o in second] == ["finished"] * 4
    assert len(read_record(trial_folder(tmp_path, "b")).launches) == 2
    assert {o.key: o.result for o in second} == {"a": {"y": 4}, "b": {"y": 9}, "c": {"y": -1}, "d": {"y": 25}}


def test_outcomes_name_why_each_trial_ended(tmp_path: Path) -> None:
    """Reasons from the trials' files; the table and the chart are written from them."""
    keys = ("t000", "t001", "t002", "t003", "t004")
    plan = {k: {"optim.lr": v} for k, v in zip(keys, (1e-3, 0.0, 3e-3, 2e-3, 5e-4))}
    job = _TrialJob(lambda point, ctx: None, plan, str(tmp_path), {})
    for key in ("t000", "t001", "t002", "t004"):
        _run_trial({"key": key}, job)
    request_stop(trial_folder(tmp_path, "t001"), BY_SCHEDULER, 2)  # it stopped at step 3, after the request
    request_stop(trial_folder(tmp_path, "t002"), BY_BUDGET, 6)
    request_stop(trial_folder(tmp_path, "t004"), BY_SCHEDULER, 4)  # judged on its last report: nothing to stop
    for key, steps, values in (("t000", (0, 2, 4), (0.2, 0.4, 0.5)), ("t001", (2, 3), (0.1, None)),
                               ("t004", (2, 4), (0.3, 0.35))):
        for i, (step, value) in enumerate(zip(steps, values)):
            entry = {"launch": 0, "time_s": 10.0 * i, "step": step} | ({"val/miou": value} if value else {})
            append_history(trial_folder(tmp_path, key), entry)
    outcomes = collect_outcomes(tmp_path, plan, {"t003": "RuntimeError: boom"}, "step")
    assert [o.reason for o in outcomes] == ["finished", "stopped", "finished", "errored", "finished"]
    assert "scheduler at 2" in outcomes[1].note and "wall-time" in outcomes[2].note and "boom" in outcomes[3].note
    files = write_tables(tmp_path, outcomes, "val/miou", "max", "step", "Sweep demo")
    table = files[0].read_text()
    assert "Best: t000 (val/miou 0.5)" in table and "| t001 | 0 | stopped | 3 |" in table
    chart = write_sweep_chart([TrialCurve(o.key, [e["time_s"] for e in o.history if "val/miou" in e],
                                          [e["val/miou"] for e in o.history if "val/miou" in e], o.reason)
                               for o in outcomes], "val/miou", "Sweep demo", "a footnote", tmp_path / "chart.png",
                              best="t000")
    assert chart.stat().st_size > 10_000


def test_concurrency_comes_from_the_cluster() -> None:
    """Two 1-CPU workers per trial fit once on 2 CPUs, fractional CPUs twice; more is refused with the fix."""
    two_cpus = [NodeResources("n", 2.0, 0.0)]
    cfg = get_recipe("synth-small")
    assert plan_concurrency(0, [cfg], two_cpus) == 1
    cfg.run.cpus_per_worker = 0.5
    assert plan_concurrency(0, [cfg], two_cpus) == 2
    with pytest.raises(InfeasibleRequest, match="--max-concurrent 3: .* use --max-concurrent 2"):
        plan_concurrency(3, [cfg], two_cpus)


BAD_SPECS = {
    "unknown field": (["--param", "optim.lrr=choice(1e-3, 1e-4)"], "optim.lrr"),
    "unknown section": (["--param", "optm.lr=choice(1e-3)"], "optm.lr"),
    "unknown distribution": (["--param", "optim.lr=gauss(0, 1)"], "optim.lr"),
    "one bound": (["--param", "optim.lr=uniform(1e-3)"], "optim.lr"),
    "bounds reversed": (["--param", "optim.lr=uniform(2, 1)"], "optim.lr"),
    "log of zero": (["--param", "optim.lr=loguniform(0, 1)"], "optim.lr"),
    "empty choice": (["--param", "optim.lr=choice()"], "optim.lr"),
    "no distribution": (["--param", "optim.lr"], "--param"),
    "range on an int field": (["--param", "optim.steps=uniform(10, 20)"], "optim.steps"),
    "value of the wrong type": (["--param", "run.workers=choice(two)"], "run.workers"),
    "value the field refuses": (["--param", "data.held_out.render=grid(fast, sharp)"], "data.held_out.render"),
    "seed twice": (["--param", "run.seed=grid(0, 1)", "--seeds", "2"], "run.seed"),
    "metric never reported": (["--param", "optim.lr=choice(1e-3)", "--metric", "val/accuracy"], "--metric"),
    "metric missing from reports": (["--param", "optim.lr=choice(1e-3)", "--set", "run.val_every=30"],
                                    "run.val_every"),
    "first rung past the budget": (["--param", "optim.lr=choice(1e-3)", "--steps", "50"], "--grace"),
    "bad mode": (["--param", "optim.lr=choice(1e-3)", "--mode", "maximum"], "--mode"),
    "workers no node can host": (["--param", "optim.lr=choice(1e-3)", "--workers", "100000"], "run.workers"),
    "more trials at once than fit": (["--param", "optim.lr=choice(1e-3)", "--max-concurrent", "100000"],
                                     "--max-concurrent"),
    "resume of nothing": (["--resume", "missing"], "missing"),
}


def _refused(args: list[str], tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> str:
    """Run ``sray sweep ARGS`` in ``tmp_path``; assert exit 2, one line on stderr, nothing written."""
    assert main(["sweep", *args, "--out", str(tmp_path / "sweeps"), "--data", str(tmp_path / "no-shards")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("sray sweep: ") and "\n" not in err, err
    assert not (tmp_path / "sweeps").exists() and not (tmp_path / "mlflow.db").exists()
    return err


@pytest.mark.parametrize("case", sorted(BAD_SPECS))
def test_bad_flags_are_refused_in_one_line(case: str, tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                           monkeypatch: pytest.MonkeyPatch) -> None:
    """Each bad spec exits 2 with one line naming the parameter, before anything starts or is written."""
    monkeypatch.chdir(tmp_path)
    args, named = BAD_SPECS[case]
    assert named in _refused(args, tmp_path, capsys)


@pytest.mark.parametrize("text, named", [("params: {optim.lr: 0.001}\n", "optim.lr"),
                                         ("params: {optim.lr: choice(1e-3)}\nbudget: 3\n", "budget"),
                                         ("params: [optim.lr\n", "not valid YAML"),
                                         ("params: {optim.lr: choice(1e-3)}\nsamples: two\n", "samples")])
def test_bad_spec_files_are_refused_in_one_line(text: str, named: str, tmp_path: Path,
                                                capsys: pytest.CaptureFixture[str],
                                                monkeypatch: pytest.MonkeyPatch) -> None:
    """A spec file's unknown key, fixed value under params, broken YAML or mistyped option: exit 2, one line."""
    monkeypatch.chdir(tmp_path)
    spec = tmp_path / "spec.yaml"
    spec.write_text(text)
    assert named in _refused([str(spec)], tmp_path, capsys)


def test_a_taken_name_is_refused(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                 monkeypatch: pytest.MonkeyPatch) -> None:
    """A new sweep never continues an old one by accident."""
    monkeypatch.chdir(tmp_path)
    (tmp_path / "sweeps" / "taken").mkdir(parents=True)
    args = ["sweep", "--param", "optim.lr=choice(1e-3)", "--name", "taken", "--out", str(tmp_path / "sweeps")]
    assert main(args) == 2
    assert "--resume taken" in capsys.readouterr().err


def test_grammar_errors_name_the_parameter() -> None:
    """The grammar alone (no config): one message per mistake, naming the parameter."""
    for bad in ("uniform(a, 1)", "choice(1, 1)", "grid(1,,2)", "loguniform(-1, 1)", "uniform(0, inf)"):
        with pytest.raises(SpecError, match="optim.lr"):
            parse_param("optim.lr", bad)
    assert parse_assignment("model.weight_hidden=choice((16, 8), (32, 16))").values == ("(16, 8)", "(32, 16)")
