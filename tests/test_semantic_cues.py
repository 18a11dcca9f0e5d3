"""Appearance-free cues for the semantic head: off is the paper's head; on, only the logits change, and only
through the cue inputs (the cue columns of the classifier's first layer)."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest
import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))
from test_model_sray import model, render, rig  # noqa: E402

from sray.model.config import SRayConfig  # noqa: E402
from sray.model.semantic_cues import CUES, semantic_cues  # noqa: E402

ALL = ("density", "depth", "height", "elevation")


def _with_cues_from(plain, cues: tuple[str, ...], cue_weight: float):
    """A model with ``cues`` whose every weight is ``plain``'s and whose cue columns are ``cue_weight``."""
    net = model(semantic_cues=cues)
    state = net.state_dict()
    for name, value in plain.state_dict().items():
        if name.endswith("classifier.0.weight"):
            state[name] = torch.cat([value, torch.full((value.shape[0], len(cues)), cue_weight)], dim=1)
        else:
            state[name] = value
    net.load_state_dict(state)
    return net


def test_off_is_the_paper_head_and_zero_cue_weights_reproduce_it() -> None:
    plain = model()
    assert all(p.classifier[0].in_features == 32 for p in (plain.coarse, plain.fine))
    r = rig()
    want = render(plain, r)
    got = render(_with_cues_from(plain, ALL, 0.0), r)
    for name in ("coarse", "fine"):
        for key in ("logits", "rgb", "depth", "opacity"):
            torch.testing.assert_close(got[name][key], want[name][key], rtol=1e-5, atol=1e-6)


def test_cues_change_the_logits_only() -> None:
    plain = model()
    r = rig()
    want, got = render(plain, r), render(_with_cues_from(plain, ALL, 0.5), r)
    for name in ("coarse", "fine"):
        for key in ("rgb", "depth", "opacity", "weights"):
            torch.testing.assert_close(got[name][key], want[name][key], rtol=1e-5, atol=1e-6)
        assert (got[name]["logits"] - want[name]["logits"]).abs().max() > 1e-3


def test_the_cues_are_the_density_depth_height_and_ray_elevation() -> None:
    sigma = torch.tensor([[0.0, 1.0, 3.0]])
    depth01 = torch.tensor([[0.1, 0.5, 0.9]])
    points = torch.tensor([[[0.0, 0.0, 0.2], [1.0, 0.0, 1.3], [2.0, 1.0, 2.5]]])
    dirs = torch.tensor([[3.0, 0.0, -4.0]])
    out = semantic_cues(CUES, sigma, depth01, points, dirs)
    want = torch.stack([torch.log1p(sigma), depth01, points[..., 2], torch.full_like(depth01, -0.8)], dim=-1)
    torch.testing.assert_close(out, want)
    torch.testing.assert_close(semantic_cues(("height", "density"), sigma, depth01, points, dirs), want[..., [0, 2]])


def test_bad_cue_names_are_refused_with_the_valid_ones() -> None:
    with pytest.raises(ValueError, match="semantic_cues.*colour.*density"):
        SRayConfig(semantic_cues=("colour",))
    with pytest.raises(ValueError, match="distinct"):
        SRayConfig(semantic_cues=("depth", "depth"))
