"""One row of the ceilings benchmark: its protocol descriptor and its scores, accumulated view by view.

Scores follow zero-shot evaluation's dataset-level protocol (one confusion matrix per scene over all its
scored views, mIoU over the classes present in that scene's ground truth, then the unweighted mean over
scenes). A pixel a row gives no prediction (:data:`~sray.platform.eval.label_transfer.UNSEEN`) is counted
as predicted in an extra "unseen" class L that is never a ground-truth class: it is a miss (a false
negative of its true class) and never a match (``label_transfer.unseen_as_class``: every held-out score
counts it so). Coverage is the share of labelled query pixels that at
least one source view sees by the row's own geometry (None for rows without one); accuracy on covered
pixels is the share of those covered pixels predicted right.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np
from torch import Tensor

from sray.model.metrics import DATASET_PROTOCOL, confusion_matrix, scene_metrics
from sray.platform.eval.label_transfer import unseen_as_class


@dataclass(frozen=True)
class RowProtocol:
    """Which inputs a row reads (every row reads the cameras)."""

    labels: str
    """Where the row's labels come from, in words."""
    geometry: str
    """How they reach the query pixels, in words ("—" for per-pixel rows)."""
    query_depth: bool = False
    """Reads the query view's ground-truth depth."""
    source_images: bool = False
    """Reads the source views' images."""
    query_image: bool = False
    """Reads the query view's own image (S-Ray never does)."""
    source_depth: bool = False
    """Reads the source views' depth."""
    source_labels: bool = False
    """Reads the source views' ground-truth labels."""
    segmenter: bool = False
    """Uses the 2D segmenter's predictions."""
    rendered_depth: bool = False
    """Reads S-Ray's rendered depth of the query view (made from the source views: not an oracle)."""

    @property
    def oracle(self) -> bool:
        """Whether the row reads the query view's ground truth (never a comparison column)."""
        return self.query_depth

    def inputs(self) -> str:
        """The inputs read, comma-separated."""
        names = {"query_depth": "query GT depth", "query_image": "query image", "source_images": "source images",
                 "source_depth": "source depth", "source_labels": "source GT labels", "segmenter": "segmenter",
                 "rendered_depth": "S-Ray rendered query depth"}
        return ", ".join(["cameras", *(text for key, text in names.items() if getattr(self, key))])


@dataclass
class CeilingRow:
    """A row's descriptor and its running scores."""

    key: str
    """Short name (``a``, ``b``, ...)."""
    title: str
    """What the row measures."""
    protocol: RowProtocol
    """Inputs it reads."""
    budget: str = ""
    """Training budget behind it (segmenter, probe, checkpoint), empty when none."""
    confusions: dict[str, Tensor] = field(default_factory=dict)
    """Per scene: (L+1, L+1) int64 confusion matrix, column L = unseen."""
    covered: int = 0
    """Labelled query pixels the row's geometry covers."""
    labelled: int = 0
    """Labelled query pixels scored."""
    covered_right: int = 0
    """Covered labelled pixels predicted right."""
    geometric: bool = True
    """Whether the row has a coverage (False for per-pixel rows that read the query image)."""
    seconds: float = 0.0
    """Seconds spent predicting, over all views."""
    views: int = 0
    """Views scored."""

    def add(self, scene: str, pred: Tensor, gt: Tensor, n_classes: int, ignore_id: int, seconds: float,
            seen: Tensor | None = None) -> None:
        """Score one view: pred (H, W) int64 class ids or UNSEEN, gt (H, W) int64 (``ignore_id`` unlabelled),
        ``seen`` (H, W) bool its geometry's coverage (required unless the row is not ``geometric``)."""
        if pred.shape != gt.shape:
            raise ValueError(f"ceilings row {self.key!r}: prediction {tuple(pred.shape)} and ground truth "
                             f"{tuple(gt.shape)} differ in size")
        if self.geometric == (seen is None):
            raise ValueError(f"ceilings row {self.key!r}: pass a coverage mask exactly for geometric rows")
        conf = confusion_matrix(unseen_as_class(pred, n_classes), gt, n_classes + 1, ignore_id)
        self.confusions[scene] = self.confusions.get(scene, 0) + conf
        labelled = gt != ignore_id
        self.labelled += int(labelled.sum())
        if seen is not None:
            self.covered += int((seen & labelled).sum())
            self.covered_right += int((seen & labelled & (pred == gt)).sum())
        self.seconds += seconds
        self.views += 1

    def summary(self, n_classes: int) -> dict[str, Any]:
        """JSON-ready scores: per scene and the unweighted mean over scenes, coverage, cost, descriptor."""
        scenes = {}
        for scene, conf in self.confusions.items():
            s = scene_metrics(conf)
            scenes[scene] = {"miou": s["miou"], "total_acc": s["total_acc"], "class_avg_acc": s["class_avg_acc"],
                             "iou_per_class": [None if math.isnan(v) else v for v in s["iou_per_class"][:n_classes]]}

        def mean(key: str) -> float | None:
            values = [b[key] for b in scenes.values()]
            return float(np.mean(values)) if values and all(math.isfinite(v) for v in values) else None

        protocol = {**asdict(self.protocol), "inputs": self.protocol.inputs()}
        return {"key": self.key, "title": self.title, "protocol": protocol,
                "oracle": self.protocol.oracle, "budget": self.budget, "metric_protocol": DATASET_PROTOCOL,
                "miou": mean("miou"), "total_acc": mean("total_acc"), "class_avg_acc": mean("class_avg_acc"),
                "coverage": self.covered / self.labelled if self.geometric and self.labelled else None,
                "acc_on_covered": self.covered_right / self.covered if self.geometric and self.covered else None,
                "seconds_per_view": self.seconds / self.views if self.views else None, "views": self.views,
                "scenes": scenes}
