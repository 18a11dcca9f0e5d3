"""The machine descriptor every stored result carries: what the CPU is, how many cores, which device, and the fixed
probe's training steps per CPU second (its content and arithmetic; never its speed)."""

from __future__ import annotations

import json
import os
from pathlib import Path

import pytest
import torch

from sray.jobs.bench import speed_store
from sray.platform.common import machine


def test_cpu_model_reads_the_first_model_name(tmp_path: Path) -> None:
    """The first ``model name`` line of /proc/cpuinfo names the CPU; a file without one falls back to the stdlib."""
    info = tmp_path / "cpuinfo"
    info.write_text("processor\t: 0\nvendor_id\t: AuthenticAMD\nmodel name\t: AMD EPYC 7B13\n\n"
                    "processor\t: 1\nmodel name\t: Other CPU\n")
    assert machine.cpu_model(info) == "AMD EPYC 7B13"
    info.write_text("processor\t: 0\n")
    assert machine.cpu_model(info) and machine.cpu_model(info) != "AMD EPYC 7B13"


def test_probe_counts_steps_per_cpu_second_and_keeps_the_rng(monkeypatch: pytest.MonkeyPatch) -> None:
    """With a CPU clock that advances 0.25 s between its two reads, 2 timed steps are 2 / 0.25 steps per CPU second;
    the caller's random stream is untouched by the probe."""
    clock = iter([10.0, 10.25])
    monkeypatch.setattr(machine.time, "process_time", lambda: next(clock))
    torch.manual_seed(123)
    expected_next = torch.rand(3)
    torch.manual_seed(123)
    assert machine.probe_steps_per_cpu_second(steps=2) == pytest.approx(8.0)
    torch.testing.assert_close(torch.rand(3), expected_next, rtol=0, atol=0)


def test_probe_batch_is_fixed_and_inside_the_images() -> None:
    """The probe's batch is the same on every call (seeded), its rays start at the query camera and pass through
    pixels of the image, and its labels are class ids of the probe's network."""
    a, b = machine.probe_batch(), machine.probe_batch()
    for key in a:
        torch.testing.assert_close(a[key], b[key], rtol=0, atol=0)
    h, w = machine.PROBE_HW
    uv = (a["dirs"][:, :2] / a["dirs"][:, 2:]) @ torch.diag(torch.tensor([w / 2, w / 2])) + torch.tensor(
        [(w - 1) / 2, (h - 1) / 2])
    assert bool(((uv >= 0) & (uv <= torch.tensor([w - 1.0, h - 1.0]))).all())
    torch.testing.assert_close(a["origins"], torch.zeros_like(a["origins"]))
    assert a["src_rgb"].shape == (machine.PROBE_VIEWS, 3, h, w)
    assert int(a["label"].max()) < machine.PROBE_MODEL.n_classes


def test_the_probe_runs_in_a_fresh_single_threaded_process_or_says_it_failed(monkeypatch, capsys) -> None:
    """The fresh process returns a positive, finite rate; a process that cannot run the probe gives None and a
    warning naming the field that will be null."""
    rate = machine.probe_in_fresh_process(steps=1)
    assert rate is not None and 0 < rate < float("inf")
    monkeypatch.setattr(machine.sys, "executable", "/nonexistent/python")
    assert machine.probe_in_fresh_process(steps=1) is None
    assert "ray_steps_per_cpu_second as null" in capsys.readouterr().err


def test_describe_machine_names_this_machine(monkeypatch: pytest.MonkeyPatch) -> None:
    """The descriptor holds exactly the four agreed fields: this CPU's model, the cores this process may use, the
    device, and the probe's figure rounded to 3 significant digits; it probes once per process."""
    calls = []
    monkeypatch.setattr(machine, "probe_in_fresh_process", lambda: calls.append(1) or 0.123456)
    machine.describe_machine.cache_clear()
    try:
        first, second = machine.describe_machine(), machine.describe_machine()
    finally:
        machine.describe_machine.cache_clear()
    assert first == second and len(calls) == 1
    assert first == {"cpu_model": machine.cpu_model(), "cores": len(os.sched_getaffinity(0)),
                     "device": torch.cuda.get_device_name(0) if torch.cuda.is_available() else "cpu",
                     "ray_steps_per_cpu_second": 0.123}


def test_a_stored_speed_row_carries_the_machine(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """``sray bench speed-accuracy --store`` keeps each row with the descriptor of the machine that measured it, and
    reads the rows back unchanged."""
    described = {"cpu_model": "Some CPU", "cores": 4, "device": "cpu", "ray_steps_per_cpu_second": 2.5}
    monkeypatch.setattr(speed_store, "describe_machine", lambda: described)
    key = {"checkpoint": "c", "setting": {"name": "fast s8 c0.9"}}
    path = speed_store.store_rows(tmp_path, key, [{"miou": 0.5}])
    assert json.loads(path.read_text())["machine"] == described
    assert speed_store.stored_rows(tmp_path, key) == [{"miou": 0.5}]
