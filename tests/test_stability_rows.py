"""The stability suite's rows come from the method registry: a method registered in a test gets its rows (and a
``--methods`` choice) and loses them when removed; the axes a row is stressed on follow from its record; every
RGB-D method's row has S-Ray given the same depth beside it; legends and headers say which rows saw the scene and
which inputs each used."""

from __future__ import annotations

from pathlib import Path

import pytest

from sray.jobs.cli import build_parser
from sray.model.config import SRayConfig
from sray.platform.common.eval_protocol import EvalProtocol
from sray.platform.finetune.methods import registry
from sray.platform.finetune.methods.method import Method
from sray.platform.stability.axes import AXES
from sray.platform.stability.rows import MODES, SuiteModels, suite_rows
from sray.platform.viz.chart_style import ChartStyle

BUILTIN = ["sray", "semantic-nerf", "2d-transfer"]
RGB = SRayConfig()
"""A checkpoint's model config that reads and trained on colours only."""


def _fake(name: str, inputs: str = "", uses_sources: bool = True) -> Method:
    """A method record that is never built (its rows are only planned and labelled here)."""
    def never(*_):
        raise AssertionError("not built in this test")

    return Method(name=name, summary="a test method", build=never, artifact_file="x.safetensors", load=never,
                  style=ChartStyle("Fake finetune", "#000000", "o"), uses_sources=uses_sources,
                  zero_shot=ChartStyle("Fake zero-shot", "#111111", "x"), eval_model=never, inputs=inputs)


def _names(methods: list[str], modes: list[str] = list(MODES), no_cra: SRayConfig | None = RGB) -> list[str]:
    return [r.name for r in suite_rows(methods, modes, RGB, no_cra)]


def test_a_registered_method_gets_its_rows_and_its_cli_choice_and_loses_them_when_removed(monkeypatch) -> None:
    def choices() -> list[str]:
        sub = next(a for a in build_parser()._actions if a.dest == "command")
        return next(a for a in sub.choices["stability"]._actions if a.dest == "methods").choices

    assert "fake-seg" not in choices()
    with monkeypatch.context() as m:
        m.setitem(registry.METHODS, "fake-seg", _fake("fake-seg", uses_sources=False))
        assert "fake-seg" in choices() and "fake-seg" in build_parser().parse_args(["stability"]).methods
        assert _names(registry.method_names()) == ["sray", "sray-no-cra", "sray-rgbd", "2d-transfer", "fake-seg",
                                                   "sray-scene", "semantic-nerf-scene", "sray-rgbd-scene",
                                                   "2d-transfer-scene", "fake-seg-scene"]
        (fake,) = [r for r in suite_rows(["fake-seg"], list(MODES), RGB, None) if not r.trained]
        assert AXES["source_views"].applies(fake) and not AXES["unseen_rays"].applies(fake)  # it uses no sources
    assert "fake-seg" not in choices() and "fake-seg" not in _names(registry.method_names())


def test_axes_follow_the_row_record() -> None:
    rows = {r.name: r for r in suite_rows(BUILTIN, list(MODES), RGB, RGB)}
    stressed = {axis: sorted(name for name, r in rows.items() if AXES[axis].applies(r)) for axis in AXES}
    assert stressed["precision"] == sorted(["sray", "sray-no-cra", "sray-rgbd", "2d-transfer"])  # zero-shot only
    assert stressed["unseen_rays"] == sorted(set(rows) - {"semantic-nerf-scene"})  # rows that render from sources
    assert stressed["blur"] == stressed["source_views"] == sorted(rows)


def test_every_rgbd_method_has_sray_given_the_depth_beside_it(monkeypatch) -> None:
    assert _names(["sray", "semantic-nerf"]) == ["sray", "sray-no-cra", "sray-scene", "semantic-nerf-scene"]
    assert _names(["sray", "2d-transfer"], ["scene"]) == ["sray-scene", "sray-rgbd-scene", "2d-transfer-scene"]
    assert _names(["2d-transfer", "sray"], no_cra=None) == ["sray-rgbd", "2d-transfer", "sray", "sray-rgbd-scene",
                                                            "2d-transfer-scene", "sray-scene"]
    assert _names(["2d-transfer"]) == ["sray-rgbd", "2d-transfer", "sray-rgbd-scene", "2d-transfer-scene"]
    # a checkpoint that reads depth already is its own RGB-D row
    by = {r.name: r for r in suite_rows(["sray", "2d-transfer"], list(MODES), RGB, None)}
    assert (by["sray-rgbd"].train_inputs, by["sray-rgbd-scene"].train_inputs) == ("rgb", "rgbd")  # what training read
    depth_read = suite_rows(["sray", "2d-transfer"], ["zero-shot"], SRayConfig(inputs="rgbd"), None)
    assert [(r.name, r.inputs, r.train_inputs) for r in depth_read] == [("sray", "rgbd", ""),  # "": as its inputs
                                                                        ("2d-transfer", "rgbd", "")]
    monkeypatch.setitem(registry.METHODS, "fake-depth", _fake("fake-depth", inputs="rgbd"))
    assert _names(["sray", "fake-depth"], ["zero-shot"], None) == ["sray", "sray-rgbd", "fake-depth"]
    rgbd = next(r for r in suite_rows(["sray", "fake-depth"], ["zero-shot"], RGB, None) if r.name == "sray-rgbd")
    request = rgbd.request(SuiteModels(Path("c"), Path("c-none"), Path("s")), "cpu")
    assert (request.checkpoint, rgbd.method, rgbd.inputs) == (Path("c"), "sray-rgbd", "rgbd")  # its method reads depth


@pytest.mark.parametrize("name, seen, inputs", [
    ("sray", "never saw the scene", "RGB"), ("sray-no-cra", "never saw the scene", "RGB"),
    ("sray-rgbd", "never saw the scene", "RGB-D"), ("2d-transfer", "never saw the scene", "RGB-D"),
    ("sray-scene", "trained on the scene", "RGB"), ("semantic-nerf-scene", "trained on the scene", "RGB"),
    ("sray-rgbd-scene", "trained on the scene", "RGB-D"), ("2d-transfer-scene", "trained on the scene", "RGB-D")])
def test_legends_and_headers_say_what_each_row_saw_and_was_given(name: str, seen: str, inputs: str) -> None:
    row = next(r for r in suite_rows(BUILTIN, list(MODES), RGB, RGB) if r.name == name)
    protocol = (EvalProtocol("rule v1", 8, 8, inputs=row.inputs, train_inputs=row.train_inputs) if row.uses_sources
                else EvalProtocol.without_sources(8))
    label = row.style(protocol).label
    assert label.endswith(f"[{seen} · {inputs}]") and row.header == f"{name} ({seen}, {inputs})"
    assert ("without CRA" in label) == (row.variant == "no-cra")
    assert ("with source depth" in label) == (row.method == "sray-rgbd")
    assert len({r.style(protocol).color for r in suite_rows(BUILTIN, list(MODES), RGB, RGB)}) == 8  # told apart
