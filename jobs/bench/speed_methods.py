"""The other registered methods ``sray bench speed-accuracy`` times beside S-Ray's settings, built as ``sray eval
--method NAME`` builds them (on the CPU, full render), a flag none of them reads refused as ``sray eval`` does."""

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
"""The request fields S-Ray's settings read."""


def other_methods() -> list[str]:
    """Methods with a zero-shot model but S-Ray and its depth twin (whose rows are the settings), in registry order."""
    return [name for name in eval_method_names() if name != SRAY and get_method(name).given_depth_of != SRAY]


def method_models(names: list[str], checkpoint: Path, segmenter: Path | None) -> dict[str, EvalModel]:
    """Method name -> its zero-shot model; ValueError names an unknown method or a flag missing or not read."""
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
