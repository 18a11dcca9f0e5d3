"""The evaluation's default render by :func:`choose_default`: the **fastest** measured setting losing at most
:data:`MAX_MIOU_LOSS` mIoU points **and** :data:`MAX_CLASS_LOSS` on every class holding :data:`MIN_CLASS_SHARE` of the
labelled pixels (rarer ones swing by tens of points) against the full render of the same views; ties: higher mIoU."""

from __future__ import annotations

from dataclasses import dataclass

from sray.model.fast_render import FastRender
from sray.platform.config.fleet_config import FinetuneSettings
from sray.platform.config.held_out_render import HeldOutRender
from sray.platform.config.train_config import DataSettings

MAX_MIOU_LOSS = 1.0
MAX_CLASS_LOSS = 3.0
MIN_CLASS_SHARE = 0.01
_FLOAT_SLACK = 1e-9
"""Points: a loss within this of its limit passes (differences of percentages carry float noise)."""


@dataclass(frozen=True)
class Measured:
    """One setting's paired measurement, as the rule reads it."""

    name: str
    miou: float
    """mIoU in %, overall."""
    seconds: float
    """Time per view, lower is faster."""
    class_iou: dict[str, float | None]
    """Class name -> IoU in % (None: absent from the ground truth)."""
    class_share: dict[str, float]
    """Class name -> its share of the labelled test pixels (0..1)."""


@dataclass(frozen=True)
class Shortfall:
    """Where a setting loses more than the rule allows."""

    where: str
    """``overall`` or the class's name."""
    loss: float
    limit: float

    def describe(self) -> str:
        """``chair -4.20`` (points, against the full render)."""
        return f"{self.where} {-self.loss:+.2f}"


@dataclass(frozen=True)
class DefaultChoice:
    """What the rule decided on one set of rows."""

    reference: str
    chosen: str
    counted: tuple[str, ...]
    """Classes holding at least ``MIN_CLASS_SHARE`` of the labelled test pixels."""
    shortfalls: dict[str, tuple[Shortfall, ...]]
    """Every setting's shortfalls (empty: it qualifies), fastest setting first."""

    def passes(self, name: str) -> bool:
        """Whether setting ``name`` qualifies (KeyError for a setting the rule was not given)."""
        return not self.shortfalls[name]

    def rejected(self) -> dict[str, tuple[Shortfall, ...]]:
        """The settings faster than the chosen one, each with why the rule rejected it, fastest first."""
        faster = list(self.shortfalls)[:list(self.shortfalls).index(self.chosen)]
        return {name: self.shortfalls[name] for name in faster}


def counted_classes(reference: Measured) -> tuple[str, ...]:
    """The classes whose share of the labelled test pixels reaches ``MIN_CLASS_SHARE``, in the reference's order."""
    return tuple(c for c, share in reference.class_share.items() if share >= MIN_CLASS_SHARE)


def shortfalls(row: Measured, reference: Measured, counted: tuple[str, ...]) -> tuple[Shortfall, ...]:
    """Where ``row`` loses more than the rule allows against ``reference``, overall first; ValueError when it has no
    IoU for a counted class (rows measured on other views)."""
    found = []
    if reference.miou - row.miou > MAX_MIOU_LOSS + _FLOAT_SLACK:
        found.append(Shortfall("overall", reference.miou - row.miou, MAX_MIOU_LOSS))
    for name in counted:
        iou, ref = row.class_iou.get(name), reference.class_iou.get(name)
        if iou is None or ref is None:
            raise ValueError(f"default render rule: setting {row.name!r} or the reference {reference.name!r} has no "
                             f"IoU for class {name!r}, which holds {100 * reference.class_share[name]:.1f}% of the "
                             "test pixels; compare rows measured on the same views")
        if ref - iou > MAX_CLASS_LOSS + _FLOAT_SLACK:
            found.append(Shortfall(name, ref - iou, MAX_CLASS_LOSS))
    return tuple(found)


def choose_default(rows: list[Measured], reference: str) -> DefaultChoice:
    """Apply the rule (module docstring) to ``rows`` against the row named ``reference`` (the full render)."""
    by_name = {r.name: r for r in rows}
    if reference not in by_name:
        raise ValueError(f"default render rule: the reference {reference!r} is not among the rows {list(by_name)}")
    ref = by_name[reference]
    counted = counted_classes(ref)
    order = sorted(range(len(rows)), key=lambda i: (rows[i].seconds, -rows[i].miou, i))
    found = {rows[i].name: shortfalls(rows[i], ref, counted) for i in order}
    chosen = next(name for name, short in found.items() if not short)
    return DefaultChoice(reference=reference, chosen=chosen, counted=counted, shortfalls=found)


def todays_defaults() -> dict[str, FastRender | None]:
    """Who uses a default render today -> its fast mode (None: full): ``sray eval``, validation (``data.held_out``),
    the fleet's held-out scores (``finetune.held_out``); the last two render all of their strided grid: ``fast s1``."""
    return {"sray eval": HeldOutRender().fast(), "validation": DataSettings().held_out.fast(),
            "fleet held-out": FinetuneSettings().held_out.fast()}
