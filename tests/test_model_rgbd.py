"""RGB-D mode (``model.inputs = rgbd``): source depth places the coarse samples; the rgb mode is unchanged.

Independent facts: the ray-plane intersection of an analytic wall, the exact ray cast of the toy
room, ``sample_uniform``'s equal bins, and an rgb model's own render.
"""

from __future__ import annotations

import numpy as np
import pytest
import torch
from toy_room import FAR, N_CLASSES, NEAR, TRAIN_IDS, first_hits, look_at, make_room, miou, one_thread, overfit

from sray.model.config import SRayConfig
from sray.model.depth_sampling import source_surface_depth, surface_samples
from sray.model.rays import image_pixels, pixel_rays
from sray.model.rendering import sample_uniform
from sray.model.runtime import Runtime
from sray.model.semantic_ray import SRayModel
from sray.model.source_set import SourceSet, rigid_inverse

WALL_Z = 3.0  # the analytic scene: the plane z = 3 (world), seen by four sources at z = 0
H, W = 32, 40
K64 = torch.tensor([[30.0, 0.0, (W - 1) / 2], [0.0, 30.0, (H - 1) / 2], [0.0, 0.0, 1.0]], dtype=torch.float64)
SOURCES = [(-0.5, 0.0), (0.5, 0.0), (0.0, -0.4), (0.0, 0.4)]
BAND = 0.1


def _camera(x: float, y: float) -> torch.Tensor:
    """float64 (4, 4) camera at (x, y, 0) looking at the wall's centre."""
    return torch.tensor(look_at(np.array([x, y, 0.0]), np.array([0.0, 0.0, WALL_Z])))


def _wall_t(c2w: torch.Tensor, K: torch.Tensor = K64) -> torch.Tensor:
    """(H*W,) exact ray parameter (= camera z-depth) where each pixel ray of ``c2w`` meets the wall."""
    o, d = pixel_rays(K, c2w, image_pixels(H, W).to(K.dtype))
    return (WALL_Z - o[:, 2]) / d[:, 2]


def _wall_sources() -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
    """rgb (m, 3, H, W) (a gradient), K (m, 3, 3), c2w (m, 4, 4), depth (m, H, W): the wall's exact depth."""
    c2w = torch.stack([_camera(x, y) for x, y in SOURCES])
    depth = torch.stack([_wall_t(c).reshape(H, W) for c in c2w]).float()
    rgb = torch.linspace(0, 1, H * W).reshape(1, 1, H, W).expand(len(SOURCES), 3, H, W).contiguous()
    return rgb, K64.float().expand(len(SOURCES), 3, 3), c2w.float(), depth


def _query(every: int = 1) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
    """origins, dirs (R, 3), near, far (R,) of every ``every``-th pixel ray of a query camera at (0.1, 0.1, 0)
    and the wall's t (R,) on them."""
    c2w = _camera(0.1, 0.1)
    o, d = pixel_rays(K64.float(), c2w.float(), image_pixels(H, W))
    n = o[::every].shape[0]
    return o[::every], d[::every], torch.full((n,), NEAR), torch.full((n,), FAR), _wall_t(c2w).float()[::every]


def _source_set(depth: torch.Tensor) -> SourceSet:
    """The wall's sources as a ``SourceSet`` (features unused by the depth rule) with ``depth``."""
    rgb, K, c2w, _ = _wall_sources()
    return SourceSet(feats=torch.zeros(len(SOURCES), 8, 8, 10), rgb=rgb, K=K, c2w=c2w, w2c=rigid_inverse(c2w),
                     depth=depth)


def test_surface_depth_of_an_analytic_plane() -> None:
    o, d, near, far, wall = _query()
    est = source_surface_depth(_source_set(_wall_sources()[3]), o, d, near, far, 64, BAND, 1e-3)
    assert not est.isnan().any()
    torch.testing.assert_close(est, wall, atol=0.02, rtol=0.0)  # probes are 0.086 apart


def test_surface_depth_is_nan_without_known_source_depth() -> None:
    o, d, near, far, _ = _query()
    est = source_surface_depth(_source_set(torch.zeros(len(SOURCES), H, W)), o, d, near, far, 64, BAND, 1e-3)
    assert est.isnan().all()


def test_surface_depth_in_a_room_with_an_occluder() -> None:
    """The toy room (walls and a crate that hides parts of the floor from some sources): against the exact
    ray cast of a training view, almost every ray's estimate lies within the band."""
    room = make_room((36, 48), focal=30.0)
    rgb, K, c2w = room.sources()
    src = SourceSet(torch.zeros(4, 8, 9, 12), rgb, K, c2w, rigid_inverse(c2w), room.source_depth())
    q = torch.tensor(room.cams[TRAIN_IDS[0]])
    o, d = pixel_rays(torch.tensor(room.K).float(), q.float(), image_pixels(*room.hw))
    n = o.shape[0]
    est = source_surface_depth(src, o, d, torch.full((n,), NEAR), torch.full((n,), FAR), 64, BAND, 1e-3)
    truth = torch.tensor(first_hits(room.K, room.cams[TRAIN_IDS[0]], room.hw, np.zeros(3))[0]).float()
    good = ((est - truth).abs() < BAND).float().mean()
    assert good > 0.9, f"only {good:.1%} of the rays within {BAND} of the true surface"


@pytest.mark.parametrize("stratified", [False, True])
@pytest.mark.parametrize("fraction", [0.25, 0.5, 1.0])
def test_the_band_holds_the_documented_share(stratified: bool, fraction: float) -> None:
    n, n_rays = 32, 6
    near, far = torch.full((n_rays,), 0.5), torch.full((n_rays,), 6.0)
    surface = torch.tensor([0.52, 1.0, 2.7, 3.3, 5.95, 6.0])  # bands clipped at near and at far, too
    z = surface_samples(near, far, surface, n, fraction, BAND, stratified, torch.Generator().manual_seed(3))
    lo, hi = (surface - BAND).clamp(0.5, 6.0), (surface + BAND).clamp(0.5, 6.0)
    in_band = ((z >= lo[:, None]) & (z <= hi[:, None])).sum(-1)
    assert in_band.tolist() == [round(fraction * n)] * n_rays
    assert (z.diff(dim=-1) >= 0).all() and (z >= 0.5).all() and (z <= 6.0).all()


@pytest.mark.parametrize("stratified", [False, True])
def test_rays_without_a_surface_get_the_rgb_samples(stratified: bool) -> None:
    near, far = torch.full((5,), 0.5), torch.full((5,), 6.0)
    surface = torch.tensor([float("nan"), 2.0, float("nan"), 4.0, float("nan")])
    z = surface_samples(near, far, surface, 16, 0.5, BAND, stratified, torch.Generator().manual_seed(1))
    plain = sample_uniform(near, far, 16, stratified, torch.Generator().manual_seed(1))
    nan = surface.isnan()
    assert torch.equal(z[nan], plain[nan]) and not torch.equal(z[~nan], plain[~nan])


def _cfg(inputs: str) -> SRayConfig:
    return SRayConfig(n_classes=4, feat_dim=8, n_heads=2, n_coarse=16, n_fine=8, geo_hidden=(16, 8),
                      dir_hidden=8, weight_hidden=(8, 4), inputs=inputs)


def _nets() -> tuple[SRayModel, SRayModel]:
    """An rgb model and an rgbd model with the same weights (an rgb state dict loads in rgbd)."""
    torch.manual_seed(0)
    rgb_net = SRayModel(_cfg("rgb")).eval()
    rgbd_net = SRayModel(_cfg("rgbd")).eval()
    rgbd_net.load_state_dict(rgb_net.state_dict())
    return rgb_net, rgbd_net


@pytest.mark.parametrize("impl", ["fast", "reference"])
def test_rgb_mode_is_unchanged_by_source_depth(impl: str) -> None:
    rgb_net, _ = _nets()
    rgb, K, c2w, depth = _wall_sources()
    o, d, near, far, _ = _query(every=9)
    run = Runtime(impl=impl)
    with torch.no_grad():
        plain = rgb_net.render_rays(rgb_net.encode(rgb, K, c2w), o, d, near, far, stratified=False, runtime=run)
        given = rgb_net.render_rays(rgb_net.encode(rgb, K, c2w, depth), o, d, near, far, stratified=False,
                                    runtime=run)
    assert torch.equal(plain["coarse"]["z"], sample_uniform(near, far, 16, stratified=False))
    for p in ("coarse", "fine"):
        for k in ("logits", "rgb", "z", "weights"):
            assert torch.equal(plain[p][k], given[p][k]), (p, k)


@pytest.mark.parametrize("impl", ["fast", "reference"])
def test_rgbd_without_known_depth_renders_as_rgb(impl: str) -> None:
    rgb_net, rgbd_net = _nets()
    rgb, K, c2w, _ = _wall_sources()
    o, d, near, far, _ = _query(every=9)
    run = Runtime(impl=impl)
    with torch.no_grad():
        a = rgb_net.render_rays(rgb_net.encode(rgb, K, c2w), o, d, near, far, stratified=False, runtime=run)
        b = rgbd_net.render_rays(rgbd_net.encode(rgb, K, c2w, torch.zeros(len(SOURCES), H, W)), o, d, near, far,
                                 stratified=False, runtime=run)
    for p in ("coarse", "fine"):
        assert torch.equal(a[p]["logits"], b[p]["logits"]) and torch.equal(a[p]["z"], b[p]["z"])


@pytest.mark.parametrize("impl", ["fast", "reference"])
def test_rgbd_coarse_samples_gather_at_the_wall(impl: str) -> None:
    _, net = _nets()
    rgb, K, c2w, depth = _wall_sources()
    o, d, near, far, wall = _query(every=9)
    with torch.no_grad():
        out = net.render_rays(net.encode(rgb, K, c2w, depth), o, d, near, far, stratified=True,
                              runtime=Runtime(impl=impl))
    z = out["coarse"]["z"]
    near_wall = ((z - wall[:, None]).abs() <= BAND + 0.02).sum(-1)
    assert (near_wall >= round(0.5 * 16)).all()
    assert (z.diff(dim=-1) >= 0).all() and (z >= NEAR).all() and (z <= FAR).all()
    assert torch.isfinite(out["fine"]["logits"]).all()


def test_bad_inputs_are_refused_naming_the_field() -> None:
    with pytest.raises(ValueError, match="`inputs`.*'depth'.*rgbd"):
        SRayConfig(inputs="depth")
    with pytest.raises(ValueError, match="`depth_fraction`"):
        SRayConfig(inputs="rgbd", depth_fraction=1.5)
    with pytest.raises(ValueError, match="`depth_band`"):
        SRayConfig(inputs="rgbd", depth_band=0.0)
    rgb, K, c2w, _ = _wall_sources()
    with pytest.raises(ValueError, match="src_depth"):
        _nets()[1].encode(rgb, K, c2w)


def test_rgbd_overfits_a_training_view_of_a_small_scene() -> None:
    """tests/test_model_overfit.py at the same tiny size, with the source depths as input."""
    room = make_room((36, 48), focal=30.0)
    with one_thread():
        net = overfit(room, SRayConfig(n_classes=N_CLASSES, n_coarse=8, n_fine=8, n_source=4, inputs="rgbd"), 120)
        with torch.no_grad():
            src = net.encode(*room.sources(), room.source_depth())
            img = net.render_image(src, torch.tensor(room.K, dtype=torch.float32),
                                   torch.tensor(room.cams[4], dtype=torch.float32), room.hw, NEAR, FAR,
                                   Runtime(chunk=512))
    score = miou(img["fine"]["logits"].argmax(-1).numpy(), room.views[4][1], N_CLASSES)
    assert score > 0.9, f"mIoU {score:.3f} after 120 rgbd steps"
