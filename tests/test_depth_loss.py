"""The training-time depth term (``model/depth_loss.py``, ``SRayConfig.lambda_depth``).

References: an L1 written out ray by ray in Python; a ray whose density is a step at a known camera z-depth,
rendered by the real renderer through a rotated camera's corner pixel (so the distance along the ray differs
from the z-depth by |d| > 1); and the loss without the term (the two-term loss, unchanged bit for bit).
"""

from __future__ import annotations

import math

import pytest
import torch
from test_model_sray import FAR, NEAR, rig

from sray.model.config import SRayConfig
from sray.model.depth_loss import DepthTarget
from sray.model.hierarchical import render_rays
from sray.model.losses import LossConfig, render_loss
from sray.model.rays import pixel_rays
from sray.model.runtime import Runtime
from sray.model.semantic_ray import SRayModel

IGNORE = 255


def _out(n_rays: int, seed: int = 0) -> dict[str, dict[str, torch.Tensor]]:
    """Two passes of random logits (3 classes), colours and depths in [0.5, 5.5], all requiring grad."""
    g = torch.Generator().manual_seed(seed)
    return {name: {"logits": torch.randn(n_rays, 3, generator=g).requires_grad_(),
                   "rgb": torch.rand(n_rays, 3, generator=g).requires_grad_(),
                   "depth": (0.5 + 5.0 * torch.rand(n_rays, generator=g)).requires_grad_()}
            for name in ("coarse", "fine")}


def _targets(n_rays: int) -> tuple[torch.Tensor, torch.Tensor]:
    g = torch.Generator().manual_seed(7)
    return torch.randint(0, 3, (n_rays,), generator=g), torch.rand(n_rays, 3, generator=g)


def test_the_depth_term_is_the_l1_over_known_depths_in_units_of_the_depth_range() -> None:
    out = _out(6)
    label, rgb = _targets(6)
    gt = [2.0, 0.0, 3.5, 1.25, 0.0, 4.0]  # rays 1 and 4: unknown depth
    near, far = [1.0, 1.0, 0.5, 1.0, 1.0, 2.0], [5.0, 5.0, 4.5, 3.0, 5.0, 6.0]
    target = DepthTarget.of_rays(torch.tensor(gt), torch.tensor(near), torch.tensor(far))
    cfg = LossConfig(lambda_sem=0.5, lambda_rgb=2.0, lambda_depth=0.3)
    total, terms = render_loss(out, label, rgb, cfg, target_depth=target)
    two_terms, _ = render_loss(out, label, rgb, cfg)
    want = {}
    for p in ("coarse", "fine"):
        depth = out[p]["depth"].tolist()
        errors = [abs(depth[i] - gt[i]) / (far[i] - near[i]) for i in range(6) if gt[i] > 0]
        want[p] = sum(errors) / len(errors)
        assert math.isclose(float(terms[f"depth_{p}"]), want[p], rel_tol=1e-6)
    assert math.isclose(float((total - two_terms).detach()), 0.3 * (want["coarse"] + want["fine"]), rel_tol=1e-5)
    total.backward()
    grad = out["fine"]["depth"].grad
    assert grad[1] == 0 and grad[4] == 0 and (grad[[0, 2, 3, 5]] != 0).all()  # unknown rays get no gradient


def test_a_batch_without_known_depth_gives_exactly_zero_with_zero_gradient() -> None:
    out = _out(4)
    label, rgb = _targets(4)
    target = DepthTarget.of_rays(torch.zeros(4), torch.full((4,), NEAR), torch.full((4,), FAR))
    total, terms = render_loss(out, label, rgb, LossConfig(lambda_sem=0.0, lambda_rgb=0.0, lambda_depth=1.0),
                               target_depth=target)
    assert float(terms["depth_coarse"]) == 0.0 and float(terms["depth_fine"]) == 0.0 and float(total.detach()) == 0.0
    total.backward()
    assert all(torch.equal(out[p]["depth"].grad, torch.zeros(4)) for p in ("coarse", "fine"))


def test_rendered_depth_is_the_z_depth_the_shards_store() -> None:
    """A surface at camera z-depth 2.75 (a step in density), seen through the corner pixel of a camera turned
    30 degrees: the renderer's depth is that z-depth (not the distance along the ray, |d| = 1.57 times longer),
    and the depth term against the stored z-depth is zero."""
    z_surface = 2.75  # a coarse bin centre of [1, 5] in 8 bins
    angle = math.radians(30.0)
    c2w = torch.eye(4)
    c2w[:3, :3] = torch.tensor([[math.cos(angle), 0.0, math.sin(angle)], [0.0, 1.0, 0.0],
                                [-math.sin(angle), 0.0, math.cos(angle)]])
    c2w[:3, 3] = torch.tensor([0.3, -0.2, 1.0])
    K = torch.tensor([[20.0, 0.0, 19.5], [0.0, 20.0, 14.5], [0.0, 0.0, 1.0]])
    origins, dirs = pixel_rays(K, c2w, torch.tensor([[0.0, 0.0]]))  # (1, 3): the top-left corner
    assert dirs.norm() > 1.5

    def field(name: str, o: torch.Tensor, d: torch.Tensor, z: torch.Tensor, lo: torch.Tensor,
              hi: torch.Tensor) -> dict[str, torch.Tensor]:
        points = o[:, None] + z[..., None] * d[:, None]  # (R, N, 3) world
        cam_z = (points - c2w[:3, 3]) @ c2w[:3, 2]  # (R, N) camera z of each point, from world geometry
        n_rays, n = z.shape
        return {"sigma": torch.where(cam_z >= z_surface - 1e-6, 1e4, 0.0), "logits": torch.zeros(n_rays, n, 3),
                "rgb": torch.zeros(n_rays, n, 3)}

    out = render_rays(field, origins, dirs, 1.0, 5.0, n_coarse=8, n_fine=64, stratified=False, fine_samples="new")
    torch.testing.assert_close(out["coarse"]["depth"], torch.tensor([z_surface]), rtol=0, atol=1e-5)
    torch.testing.assert_close(out["fine"]["depth"], torch.tensor([z_surface]), rtol=0, atol=0.5 / 64)
    cfg = LossConfig(lambda_sem=0.0, lambda_rgb=0.0, lambda_depth=1.0)
    near, far = torch.tensor([1.0]), torch.tensor([5.0])
    _, terms = render_loss(out, torch.tensor([IGNORE]), torch.zeros(1, 3), cfg,
                           target_depth=DepthTarget.of_rays(torch.tensor([z_surface]), near, far))
    assert float(terms["depth_coarse"]) < 1e-5
    distance = z_surface * float(dirs.norm())
    _, terms = render_loss(out, torch.tensor([IGNORE]), torch.zeros(1, 3), cfg,
                           target_depth=DepthTarget.of_rays(torch.tensor([distance]), near, far))
    assert float(terms["depth_coarse"]) > 0.15  # a distance-along-the-ray target would be far off


def test_weight_zero_or_no_target_leaves_the_loss_and_its_terms_exactly_as_before() -> None:
    """``lambda_depth = 0`` with a depth target is the two-term loss bit for bit (value, terms, gradients), in one
    pass and in pieces."""
    r = rig(m=3)
    n = r["origins"].shape[0]
    label, rgb = _targets(n)
    depth = torch.linspace(0.0, 4.0, n)
    results = []
    for piece, with_depth in ((0, False), (0, True), (12, False), (12, True)):
        torch.manual_seed(0)
        net = SRayModel(SRayConfig(n_classes=3, feat_dim=8, n_coarse=6, n_fine=6))
        torch.manual_seed(3)
        src = net.encode(r["rgb"], r["K"], r["c2w"])
        loss, terms = net.training_loss(src, r["origins"], r["dirs"], NEAR, FAR, label, rgb,
                                        Runtime(train_piece=piece), depth if with_depth else None)
        loss.backward()
        results.append((loss, terms, [p.grad for p in net.parameters()]))
    for plain, with_target in ((results[0], results[1]), (results[2], results[3])):
        assert torch.equal(plain[0], with_target[0])
        assert list(plain[1]) == list(with_target[1]) and not any(k.startswith("depth") for k in plain[1])
        assert all(torch.equal(a, b) for a, b in zip(plain[1].values(), with_target[1].values()))
        assert all((a is None and b is None) or torch.equal(a, b) for a, b in zip(plain[2], with_target[2]))


def test_a_negative_or_nan_weight_is_refused_naming_the_field() -> None:
    for bad in (-0.1, float("nan")):
        with pytest.raises(ValueError, match="field `lambda_depth`.*use 0 \\(no depth loss\\) or a positive weight"):
            SRayConfig(lambda_depth=bad)
    assert SRayConfig().train_inputs == "rgb" and SRayConfig(lambda_depth=0.1).train_inputs == "rgbd"
