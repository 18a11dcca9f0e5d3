"""The stability suite's rows, read off the method registry, and what legends say a row saw (docs/stability.md)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from sray.model.config import SRayConfig
from sray.platform.common.eval_protocol import EvalProtocol
from sray.platform.finetune.methods.method import EvalRequest
from sray.platform.finetune.methods.registry import get_method, with_depth_twins
from sray.platform.viz.chart_style import ChartStyle

MODES = ("zero-shot", "scene")
"""``zero-shot``: pretrained models with no per-scene step; ``scene``: trained on the test scene's views."""
INPUT_WORDS = {"rgb": "RGB", "rgbd": "RGB-D"}
"""How legends and headers name a protocol's ``inputs``."""
SEEN_WORDS = {False: "never saw the scene", True: "trained on the scene"}
"""How legends and headers say whether a row saw the scene it is scored on."""
VARIANT_WORDS = {"": "", "no-cra": ", without CRA"}
"""Variant -> the words added to the method's label."""
VARIANT_LOOKS = {("no-cra", False): ChartStyle("", "#2ca02c", "^")}
"""(variant, trained) -> the colour and marker its row is drawn with (the method's own where none is listed)."""


@dataclass(frozen=True)
class SuiteModels:
    """The pretrained models a run stresses, given (``--checkpoint``, ...) or pretrained by the preset's world."""

    checkpoint: Path
    """S-Ray checkpoint folder: the zero-shot S-Ray rows, and the shared model every trained row is built with."""
    checkpoint_no_cra: Path | None = None
    """S-Ray checkpoint trained with ``model.attention=none`` (None: no ``-no-cra`` row)."""
    segmenter: Path | None = None
    """2D segmenter folder (``sray bench segmenter``) of ``2d-transfer``."""


@dataclass(frozen=True)
class Row:
    """One line of the suite's charts and one column pair of its tables."""

    name: str
    """Its key (points, tables, tracked metrics): ``<method>[-no-cra][-scene]``."""
    method: str
    trained: bool
    """Trained on the test scene (else zero-shot)."""
    variant: str
    """``""`` or ``no-cra`` (the no-CRA checkpoint)."""
    inputs: str
    """What it is given of the source views (``EvalProtocol.inputs``): ``rgb`` or ``rgbd``."""
    uses_sources: bool
    """Held-out views are rendered from source views (else from none: a per-scene model)."""
    train_inputs: str = ""
    """What its training read besides colours and labels (``EvalProtocol.train_inputs``; empty: as ``inputs``)."""

    def protocol(self, shards: Path, n_source: int, stride: int) -> EvalProtocol:
        """How its scores are made: ``n_source`` fixed sources given as its ``inputs``, or none."""
        if self.uses_sources:
            return EvalProtocol.from_shards(shards, n_source, stride, self.inputs, self.train_inputs)
        return EvalProtocol.without_sources(stride)

    @property
    def header(self) -> str:
        """Table header: its name, whether it saw the scene and its inputs."""
        return f"{self.name} ({SEEN_WORDS[self.trained]}, {INPUT_WORDS[self.inputs]})"

    def request(self, models: SuiteModels, device: str) -> EvalRequest:
        """What the method's ``eval_model`` builds this zero-shot row's model from (the full render)."""
        checkpoint = models.checkpoint_no_cra if self.variant == "no-cra" else models.checkpoint
        return EvalRequest(checkpoint=checkpoint, segmenter=models.segmenter, device=device, fast=None)

    def style(self, protocol: EvalProtocol) -> ChartStyle:
        """Legend and look: the method's label for the mode, the variant, whether it saw the scene, its inputs."""
        method = get_method(self.method)
        base = method.style if self.trained else method.zero_shot or ChartStyle(
            f"{method.name} zero-shot", method.style.color, method.style.marker)
        look = VARIANT_LOOKS.get((self.variant, self.trained), base)
        tag = f"[{SEEN_WORDS[self.trained]} · {INPUT_WORDS[protocol.inputs]}]"
        label = f"{base.label}{VARIANT_WORDS[self.variant]} {tag}"
        return ChartStyle(label, look.color, look.marker)


def _row(method: str, trained: bool, variant: str, inputs: str, train_inputs: str = "") -> Row:
    suffix = (f"-{variant}" if variant else "") + ("-scene" if trained else "")
    return Row(f"{method}{suffix}", method, trained, variant, inputs, get_method(method).uses_sources, train_inputs)


def mode_rows(methods: list[str], trained: bool, checkpoint: SRayConfig, no_cra: SRayConfig | None) -> list[Row]:
    """The rows of one mode, in the order of ``methods`` with the depth twins and the no-CRA row placed."""
    rows = []
    for name in with_depth_twins(methods, checkpoint.inputs):
        record = get_method(name)
        if not trained and record.eval_model is None:
            continue
        if record.given_depth_of:  # its training read the depth only when it was trained on the scene with it
            rows.append(_row(name, trained, "", record.inputs, "rgbd" if trained else checkpoint.inputs))
        elif record.inputs or not record.uses_sources:  # it does not read the sources as the checkpoint does
            rows.append(_row(name, trained, "", record.inputs or "rgb"))
        else:
            rows.append(_row(name, trained, "", checkpoint.inputs))
            if not trained and no_cra is not None:
                rows.append(_row(name, trained, "no-cra", no_cra.inputs))
    return rows


def suite_rows(methods: list[str], modes: list[str], checkpoint: SRayConfig, no_cra: SRayConfig | None) -> list[Row]:
    """Every row of ``methods`` in ``modes``, zero-shot first, by the S-Ray and no-CRA (or None) checkpoint configs."""
    unknown = [m for m in modes if m not in MODES]
    if unknown:
        raise ValueError(f"stability modes {unknown}: use {list(MODES)}")
    return [row for trained in (False, True) if MODES[trained] in modes
            for row in mode_rows(methods, trained, checkpoint, no_cra)]
