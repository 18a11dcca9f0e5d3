"""The other registered methods ``sray bench speed-accuracy`` times beside S-Ray's render settings: every method with a
zero-shot model (a registry record with an ``eval_model``) but S-Ray, whose rows are the settings themselves (its
depth twin ``sray-rgbd`` too: those are the settings that render with ``inputs=rgbd``).

A method's model is built from its record as ``sray eval --method NAME`` builds it, from the bench's flags
(``--checkpoint``, ``--segmenter``), on the CPU and with its full render; a flag none of the chosen methods reads
is refused (``sray.jobs.methods.flags``), as ``sray eval`` refuses it.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

from sray.jobs.methods.flags import refusal, unread_flags
from sray.platform.finetune.methods.method import EvalRequest
from sray.platform.finetune.methods.registry import eval_method_names, get_method
from sray.platform.finetune.methods.sray_method import NAME as SRAY

if TYPE_CHECKING:
    from sray.platform.eval.eval_model import EvalModel

SETTINGS_READ = ("checkpoint",)
"""The request fields S-Ray's settings read (the bench renders ``--checkpoint`` itself)."""


def other_methods() -> list[str]:
    """Registered methods the bench can time beside S-Ray's settings (``--methods`` choices), in registry order."""
    return [name for name in eval_method_names() if name != SRAY and get_method(name).given_depth_of != SRAY]


def method_models(names: list[str], checkpoint: Path, segmenter: Path | None) -> dict[str, EvalModel]:
    """Method name -> its zero-shot model on the CPU, full render, built by its registry record from these flags.

    ValueError names a method that is not one of :func:`other_methods`, a flag a method needs (``--segmenter``),
    or ``--segmenter`` given while no chosen method reads it; FileNotFoundError a missing file.
    """
    unknown = [n for n in names if n not in other_methods()]
    if unknown:
        raise ValueError(f"--methods: {unknown} have no zero-shot model to time beside S-Ray's settings; choose from "
                         f"{other_methods()}")
    reads = {*SETTINGS_READ, *(field for n in names for field in get_method(n).eval_reads)}
    unread = unread_flags(["--segmenter"] if segmenter is not None else [], reads)
    if unread:
        raise ValueError(refusal(unread, f"--methods {' '.join(names) or '(none)'}", reads))
    request = EvalRequest(checkpoint=checkpoint, segmenter=segmenter, device="cpu", fast=None)
    return {name: get_method(name).eval_model(request) for name in dict.fromkeys(names)}
