"""The rows of the stability suite, read off the method registry: which model of which method is stressed, in
which mode, and how its legend and table header name what it saw and what it was given.

Every registered method (:mod:`sray.platform.finetune.methods.registry`) gives up to two rows:

* ``<name>``, **zero-shot**: its pretrained model with no per-scene step, built by its ``eval_model`` from the
  suite's given models (a method without one, as Semantic-NeRF, has no zero-shot row);
* ``<name>-scene``, **trained on the scene**: its fleet learner (``Method.build``) trained on the test scene's views
  for the suite's one CPU-second budget, the same for every method (``Preset.scene_cpu_seconds``).

A method that renders from source views and reads them as its checkpoint does (``uses_sources`` and an empty
``inputs``: S-Ray) also gets ``<name>-no-cra``, zero-shot, from the checkpoint trained with ``model.attention=none``,
when one is given.

The methods stressed are the asked ones with the registry's depth twins placed
(:func:`~sray.platform.finetune.methods.registry.with_depth_twins`): wherever a method that reads the source depth
(``2d-transfer``) has a row, ``sray-rgbd`` (the checkpoint given the source views' depth, docs/model.md "RGB-D
mode") has one just before it, even when it was not asked for.

Which axes stress a row follows from the row too (:meth:`sray.platform.stability.axes.Axis.applies`).
"""

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
    """The pretrained models a run stresses, given (``--checkpoint``, ``--checkpoint-no-cra``, ``--segmenter``) or
    pretrained by the preset's own world."""

    checkpoint: Path
    """S-Ray training checkpoint folder: the zero-shot S-Ray rows, and the shared model every trained row's method
    is built with (as a fleet's checkpoint)."""
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
    """The registered method it runs."""
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

    @property
    def mode(self) -> str:
        """``scene`` or ``zero-shot`` (:data:`MODES`)."""
        return MODES[1] if self.trained else MODES[0]

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
        """Legend and look: the method's own label for the mode, the variant, whether it saw the scene and the
        inputs its ``protocol`` names."""
        method = get_method(self.method)
        base = method.style if self.trained else method.zero_shot or ChartStyle(
            f"{method.name} zero-shot", method.style.color, method.style.marker)
        look = VARIANT_LOOKS.get((self.variant, self.trained), base)
        tag = f"[{SEEN_WORDS[self.trained]} · {INPUT_WORDS[protocol.inputs]}]"
        label = f"{base.label}{VARIANT_WORDS[self.variant]} {tag}"
        return ChartStyle(label, look.color, look.marker)


def follows_checkpoint(method: str) -> bool:
    """Whether the method renders from source views and reads them as its checkpoint does (S-Ray)."""
    record = get_method(method)
    return record.uses_sources and not record.inputs


def _row(method: str, trained: bool, variant: str, inputs: str, train_inputs: str = "") -> Row:
    suffix = (f"-{variant}" if variant else "") + ("-scene" if trained else "")
    return Row(f"{method}{suffix}", method, trained, variant, inputs, get_method(method).uses_sources, train_inputs)


def mode_rows(methods: list[str], trained: bool, checkpoint: SRayConfig, no_cra: SRayConfig | None) -> list[Row]:
    """The rows of one mode (see the module doc), in the order of ``methods`` with the depth twins and the no-CRA
    row placed."""
    rows = []
    for name in with_depth_twins(methods, checkpoint.inputs):
        record = get_method(name)
        if not trained and record.eval_model is None:
            continue
        if record.given_depth_of:  # its training read the depth only when it was trained on the scene with it
            rows.append(_row(name, trained, "", record.inputs, "rgbd" if trained else checkpoint.inputs))
        elif not follows_checkpoint(name):
            rows.append(_row(name, trained, "", record.inputs or "rgb"))
        else:
            rows.append(_row(name, trained, "", checkpoint.inputs))
            if not trained and no_cra is not None:
                rows.append(_row(name, trained, "no-cra", no_cra.inputs))
    return rows


def suite_rows(methods: list[str], modes: list[str], checkpoint: SRayConfig, no_cra: SRayConfig | None) -> list[Row]:
    """Every row of ``methods`` (registered names) in ``modes``, zero-shot rows first. ``checkpoint``: the S-Ray
    checkpoint's model config (its ``inputs``); ``no_cra``: the no-CRA checkpoint's (None: none
    given, no row)."""
    unknown = [m for m in modes if m not in MODES]
    if unknown:
        raise ValueError(f"stability modes {unknown}: use {list(MODES)}")
    return [row for trained in (False, True) if MODES[trained] in modes
            for row in mode_rows(methods, trained, checkpoint, no_cra)]
