"""How an evaluation number was made: :class:`EvalProtocol`, in every metrics JSON (``"protocol"``), once per
training run (tag ``sray.protocol``, params ``protocol.*``) and under every table (:meth:`~EvalProtocol.describe`)."""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import asdict, dataclass, fields, replace
from pathlib import Path
from typing import Any

from sray.data_tools.shards.manifest import Manifest, read_manifest
from sray.model.fast_render import FastRender
from sray.model.metrics import DATASET_PROTOCOL, PER_IMAGE_PROTOCOL

RENDER_MODES = ("full", "fast")
"""``full``: the hierarchical renderer; ``fast``: ``sray.model.fast_render``, its settings following."""
INPUTS = ("rgb", "rgbd")
"""What the model is given of its source views: colour only, or also their depth (``SRayConfig.inputs``)."""
INPUT_NAMES = {"rgb": "RGB", "rgbd": "RGB-D"}
"""How tables and legends name each of :data:`INPUTS`."""
NO_SOURCES = "none (per-scene model)"
"""``source_rule`` of a method that renders without source views (Semantic-NeRF)."""


def inputs_name(inputs: str) -> str:
    """``RGB`` or ``RGB-D`` for a protocol's ``inputs``; ValueError naming the known ones otherwise."""
    if inputs not in INPUT_NAMES:
        raise ValueError(f"eval protocol: inputs is {inputs!r}; use one of {INPUTS}")
    return INPUT_NAMES[inputs]


def _ordinal(n: int) -> str:
    """2 -> '2nd', 3 -> '3rd', 4 -> '4th', 11 -> '11th'."""
    suffix = "th" if 10 <= n % 100 <= 20 else {1: "st", 2: "nd", 3: "rd"}.get(n % 10, "th")
    return f"{n}{suffix}"


LATER_FIELDS = ("train_inputs",)
"""Fields added after descriptors were first stored: a stored descriptor may lack them (the default applies)."""


@dataclass(frozen=True)
class EvalProtocol:
    """How a set of evaluation scores was made (JSON: :meth:`to_json`, one line: :meth:`describe`)."""

    source_rule: str
    """``"<rule> v<version>"``: the manifest's neighbour rule ranking the fixed sources, or :data:`NO_SOURCES`."""
    n_source: int
    """Source views per query view (0 with :data:`NO_SOURCES`)."""
    stride: int
    """Every ``stride``-th pixel in each direction is rendered and scored; 1 = whole images."""
    render: str = "full"
    """Render mode, one of :data:`RENDER_MODES` (``fast`` followed by its settings)."""
    inputs: str = "rgb"
    """Source-view inputs, one of :data:`INPUTS`."""
    train_inputs: str = ""
    """What the model's training read besides colours and labels (:data:`INPUTS`): ``rgbd`` for ground-truth depth
    (a ``sray-rgbd`` scene finetune), else ``rgb``; empty (the default) means ``inputs`` and is filled with it."""
    miou: str = DATASET_PROTOCOL
    """Protocol of ``miou`` and the accuracies (one confusion matrix per scene)."""
    miou_per_image: str = PER_IMAGE_PROTOCOL
    """Protocol of ``miou_per_image``."""

    def __post_init__(self) -> None:
        """ValueError naming the field that is out of range."""
        if self.stride < 1:
            raise ValueError(f"eval protocol: stride is {self.stride}; it must be >= 1 (1 = whole images)")
        if self.n_source < 0 or (self.n_source == 0) != (self.source_rule == NO_SOURCES):
            raise ValueError(f"eval protocol: n_source {self.n_source} with source_rule {self.source_rule!r}; "
                             f"n_source is 0 exactly when the rule is {NO_SOURCES!r}")
        if self.render.split(" ")[0] not in RENDER_MODES:
            raise ValueError(f"eval protocol: render is {self.render!r}; use one of {RENDER_MODES}")
        if self.inputs not in INPUTS:
            raise ValueError(f"eval protocol: inputs is {self.inputs!r}; use one of {INPUTS}")
        if not self.train_inputs:
            object.__setattr__(self, "train_inputs", self.inputs)  # frozen: filled once, here
        if self.train_inputs not in INPUTS:
            raise ValueError(f"eval protocol: train_inputs is {self.train_inputs!r}; use one of {INPUTS} "
                             "(or leave it empty: the same as inputs)")

    @classmethod
    def from_manifest(cls, manifest: Manifest, n_source: int, stride: int,
                      where: str = "manifest.json", inputs: str = "rgb", train_inputs: str = "") -> EvalProtocol:
        """The protocol of fixed sources ranked by ``manifest``'s neighbour rule (``where`` names it in errors)."""
        rule, version = manifest.neighbours.get("rule"), manifest.neighbours.get("version")
        if not rule or version is None:
            raise ValueError(f"{where}: field 'neighbours' has no 'rule' and 'version' ({manifest.neighbours}); "
                             "re-run `sray data shard` with this sray")
        return cls(source_rule=f"{rule} v{version}", n_source=n_source, stride=stride, inputs=inputs,
                   train_inputs=train_inputs)

    @classmethod
    def from_shards(cls, shards: Path, n_source: int, stride: int, inputs: str = "rgb",
                    train_inputs: str = "") -> EvalProtocol:
        """:meth:`from_manifest` of ``shards/manifest.json``."""
        return cls.from_manifest(read_manifest(Path(shards)), n_source, stride, str(Path(shards) / "manifest.json"),
                                 inputs, train_inputs)

    @classmethod
    def without_sources(cls, stride: int) -> EvalProtocol:
        """The protocol of a per-scene model that renders from no source views (Semantic-NeRF)."""
        return cls(source_rule=NO_SOURCES, n_source=0, stride=stride)

    @classmethod
    def from_json(cls, d: dict[str, Any]) -> EvalProtocol:
        """Inverse of :meth:`to_json`; ValueError names missing (but :data:`LATER_FIELDS`) or unknown fields."""
        if not isinstance(d, dict):
            raise ValueError(f"eval protocol {d!r}: expected a JSON object (docs/CONTRACTS.md); a file written "
                             "before sray recorded protocol descriptors: evaluate again to replace it")
        names = {f.name for f in fields(cls)}
        missing, unknown = sorted(names - set(LATER_FIELDS) - set(d)), sorted(set(d) - names)
        if missing or unknown:
            raise ValueError(f"eval protocol {d}: fields {missing} missing, {unknown} unknown "
                             f"(expected {sorted(names)}; see docs/CONTRACTS.md)")
        return cls(**d)

    def to_json(self) -> dict[str, Any]:
        """``{"source_rule", "n_source", "stride", "render", "inputs", "train_inputs", "miou", "miou_per_image"}``."""
        return asdict(self)

    @property
    def scores_ssim(self) -> bool:
        """SSIM is computed on whole images (``stride == 1``) only."""
        return self.stride == 1

    def rendered_by(self, fast: FastRender | None) -> EvalProtocol:
        """This protocol with the render that made the scores: ``fast``'s description, or unchanged (full)."""
        return replace(self, render=fast.describe()) if fast is not None else self

    def describe(self) -> str:
        """One line for table captions and chart footnotes."""
        sources = (NO_SOURCES if self.n_source == 0 else
                   f"{self.n_source} per query, fixed, top-ranked by {self.source_rule}")
        pixels = ("whole images (stride 1)" if self.scores_ssim else
                  f"every {_ordinal(self.stride)} in each direction (stride {self.stride}), so no SSIM")
        trained = "" if self.train_inputs == self.inputs else f" (training read {self.train_inputs})"
        return (f"sources: {sources}; pixels: {pixels}; render: {self.render}; inputs: {self.inputs}{trained}; "
                f"mIoU: {self.miou}; mIoU/img: {self.miou_per_image}")


def results_inputs(results: Iterable[dict[str, Any]], method: str) -> str:
    """The inputs ``method``'s fleet results record (``RGB``, ``RGB-D``, joined by ``/``; empty without any)."""
    found = {EvalProtocol.from_json(r["protocol"]).inputs for r in results
             if r["method"] == method and r.get("protocol") is not None}
    return "/".join(inputs_name(i) for i in sorted(found))


def caption_lines(labelled: Iterable[tuple[str, dict[str, Any] | None]]) -> list[str]:
    """``Protocol: ...`` lines for (row label, protocol JSON or None) pairs: one per protocol, naming rows if many."""
    labels: dict[str, list[str]] = {}
    for label, protocol in labelled:
        if protocol is not None:
            rows = labels.setdefault(EvalProtocol.from_json(protocol).describe(), [])
            if label not in rows:
                rows.append(label)
    if len(labels) == 1:
        return [f"Protocol: {next(iter(labels))}"]
    return [f"Protocol ({', '.join(rows)}): {text}" for text, rows in labels.items()]
