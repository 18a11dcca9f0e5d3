"""Semantic-NeRF baseline: architecture properties and a per-scene overfit on an analytic room."""

from __future__ import annotations

import math
import time
from collections.abc import Iterator

import pytest
import torch

from sray.model.losses import render_loss
from sray.model.metrics import confusion_matrix, scene_metrics
from sray.model.positional_encoding import PositionalEncoding
from sray.model.semantic_nerf import (
    SemanticNeRF,
    SemanticNeRFConfig,
    SemanticNeRFField,
    scene_box_from_cameras,
)

SMALL = {"depth": 4, "width": 64, "skip_layer": 2, "color_width": 32, "semantic_width": 32}


def test_positional_encoding_of_known_values() -> None:
    enc = PositionalEncoding(3, 2)
    x = torch.tensor([[0.25, -0.5, 1.0]])
    got = enc(x)[0]
    assert enc.out_dim == 3 * (1 + 2 * 2) == got.shape[0]
    expected = [0.25, -0.5, 1.0]
    for k in range(2):
        f = math.pi * 2**k
        expected += [math.sin(f * v) for v in (0.25, -0.5, 1.0)]
        expected += [math.cos(f * v) for v in (0.25, -0.5, 1.0)]
    torch.testing.assert_close(got, torch.tensor(expected), atol=1e-6, rtol=0.0)
    assert PositionalEncoding(3, 10).out_dim == 63 and PositionalEncoding(3, 4).out_dim == 27


def test_paper_defaults_and_skip_connection() -> None:
    cfg = SemanticNeRFConfig(n_classes=7)
    field = SemanticNeRFField(cfg)
    assert len(field.trunk) == 8
    assert [layer.in_features for layer in field.trunk] == [63, 256, 256, 256, 256, 319, 256, 256]
    assert field.color[0].in_features == 256 + 27 and field.color[0].out_features == 128
    # With every layer before the skip zeroed, the output still depends on the position:
    # the encoded input reaches the trunk again through the skip connection.
    small = SemanticNeRFField(SemanticNeRFConfig(n_classes=3, **SMALL))
    with torch.no_grad():
        for layer in small.trunk[:2]:
            layer.weight.zero_()
            layer.bias.zero_()
    x = torch.tensor([[0.1, 0.2, 0.3], [-0.4, 0.5, 0.0]])
    d = torch.tensor([[0.0, 0.0, 1.0], [0.0, 0.0, 1.0]])
    _, _, logits = small(x, d)
    assert float((logits[0] - logits[1]).detach().abs().max()) > 1e-4


def test_semantics_and_density_do_not_depend_on_direction() -> None:
    torch.manual_seed(0)
    field = SemanticNeRFField(SemanticNeRFConfig(n_classes=4, **SMALL))
    x = torch.rand(10, 3) * 2 - 1
    d1 = torch.nn.functional.normalize(torch.randn(10, 3), dim=-1)
    d2 = torch.nn.functional.normalize(torch.randn(10, 3), dim=-1)
    with torch.no_grad():
        s1, c1, l1 = field(x, d1)
        s2, c2, l2 = field(x, d2)
    torch.testing.assert_close(l1, l2, atol=0.0, rtol=0.0)
    torch.testing.assert_close(s1, s2, atol=0.0, rtol=0.0)
    assert float((c1 - c2).abs().max()) > 1e-5  # colour does see the direction
    assert bool((s1 >= 0).all())


def test_render_rays_shapes_and_determinism() -> None:
    torch.manual_seed(0)
    model = SemanticNeRF(SemanticNeRFConfig(n_classes=5, n_coarse=8, n_fine=12, **SMALL))
    origins, dirs = torch.zeros(6, 3), torch.randn(6, 3)
    out = model.render_rays(origins, dirs, 0.5, torch.full((6,), 3.0), stratified=False)
    for name, n in (("coarse", 8), ("fine", 20)):
        p = out[name]
        assert p["logits"].shape == (6, 5) and p["rgb"].shape == (6, 3)
        assert p["depth"].shape == (6,) and p["opacity"].shape == (6,)
        assert p["weights"].shape == (6, n) and p["z"].shape == (6, n)
        assert bool((p["z"][:, 1:] >= p["z"][:, :-1]).all())
    again = model.render_rays(origins, dirs, 0.5, 3.0, stratified=False)
    torch.testing.assert_close(again["fine"]["rgb"], out["fine"]["rgb"], atol=0.0, rtol=0.0)
    g1, g2 = torch.Generator().manual_seed(3), torch.Generator().manual_seed(3)
    a = model.render_rays(origins, dirs, 0.5, 3.0, True, generator=g1)["fine"]["z"]
    b = model.render_rays(origins, dirs, 0.5, 3.0, True, generator=g2)["fine"]["z"]
    torch.testing.assert_close(a, b, atol=0.0, rtol=0.0)


def test_rendering_is_independent_of_the_direction_length() -> None:
    torch.manual_seed(1)
    model = SemanticNeRF(SemanticNeRFConfig(n_classes=3, n_coarse=16, n_fine=16, **SMALL))
    origins, dirs = torch.randn(5, 3) * 0.1, torch.randn(5, 3)
    # The same segments [0.4, 2.4] |d| in world units, parameterised with d and with 2 d.
    a = model.render_rays(origins, dirs, 0.4, 2.4, stratified=False)["fine"]
    b = model.render_rays(origins, 2 * dirs, 0.2, 1.2, stratified=False)["fine"]
    for key in ("rgb", "logits", "opacity"):
        torch.testing.assert_close(a[key], b[key], atol=1e-5, rtol=1e-4)
    torch.testing.assert_close(a["depth"], 2 * b["depth"], atol=1e-5, rtol=1e-4)


def test_bad_config_names_the_field() -> None:
    with pytest.raises(ValueError, match="skip_layer"):
        SemanticNeRFConfig(n_classes=3, depth=4, skip_layer=4)
    with pytest.raises(ValueError, match="scene_scale"):
        SemanticNeRFConfig(n_classes=3, scene_scale=0.0)
    model = SemanticNeRF(SemanticNeRFConfig(n_classes=3, n_coarse=4, n_fine=4, **SMALL))
    with pytest.raises(ValueError, match=r"`near` must be a scalar or \(6,\)"):
        model.render_rays(torch.zeros(6, 3), torch.ones(6, 3), torch.zeros(5), 2.0, False)


# --- Analytic scene: a closed room [-2, 2] x [-2, 2] x [0, 2.5] (world z up) with a box. -------

ROOM_LO, ROOM_HI = torch.tensor([-2.0, -2.0, 0.0]), torch.tensor([2.0, 2.0, 2.5])
BOX_LO, BOX_HI = torch.tensor([-0.4, -0.5, 0.0]), torch.tensor([0.5, 0.4, 0.9])
BASE_COLOUR = torch.tensor([[0.7, 0.5, 0.3], [0.9, 0.9, 0.8], [0.3, 0.5, 0.8], [0.8, 0.2, 0.2]])
HEIGHT, WIDTH = 24, 32
K_TEST = torch.tensor([[18.0, 0.0, (WIDTH - 1) / 2], [0.0, 18.0, (HEIGHT - 1) / 2], [0, 0, 1.0]])


def _look_at(eye: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
    """c2w (4, 4) in OpenCV axes (x right, y down, z forward) for a world with z up."""
    z = torch.nn.functional.normalize(target - eye, dim=0)
    x = torch.nn.functional.normalize(torch.linalg.cross(z, torch.tensor([0.0, 0.0, 1.0])), dim=0)
    y = torch.linalg.cross(z, x)
    c2w = torch.eye(4)
    c2w[:3, :3] = torch.stack([x, y, z], dim=1)
    c2w[:3, 3] = eye
    return c2w


def _cast(origins: torch.Tensor, dirs: torch.Tensor) -> tuple[torch.Tensor, ...]:
    """Hit parameter t (R,), label (R,) and colour (R, 3): floor 0, walls 1, ceiling 2, box 3."""
    t_lo, t_hi = (ROOM_LO - origins) / dirs, (ROOM_HI - origins) / dirs  # (R, 3)
    t_wall, axis = torch.maximum(t_lo, t_hi).min(-1)  # exit of the room (origins inside)
    up = dirs[torch.arange(len(dirs)), axis] > 0
    label = torch.where(axis == 2, torch.where(up, 2, 0), torch.ones_like(axis))
    b_lo, b_hi = (BOX_LO - origins) / dirs, (BOX_HI - origins) / dirs
    t_in = torch.minimum(b_lo, b_hi).max(-1).values
    t_out = torch.maximum(b_lo, b_hi).min(-1).values
    in_box = (t_in <= t_out) & (t_in > 0) & (t_in < t_wall)
    t = torch.where(in_box, t_in, t_wall)
    label = torch.where(in_box, 3, label)
    hit = origins + t[:, None] * dirs
    checker = ((hit[:, 0] * 2).floor() + (hit[:, 1] * 2).floor() + (hit[:, 2] * 2).floor()) % 2
    colour = BASE_COLOUR[label] * (0.75 + 0.25 * checker[:, None])
    return t, label, colour


def _room_views() -> list[dict[str, torch.Tensor]]:
    """Six views from a 2 x 3 grid of positions facing the box and the far wall (like a hand-held
    capture); rays built here, independently of sray.model.rays. Every view sees all 4 classes."""
    views = []
    v, u = torch.meshgrid(torch.arange(HEIGHT, dtype=torch.float32),
                          torch.arange(WIDTH, dtype=torch.float32), indexing="ij")
    pix = torch.stack([u, v, torch.ones_like(u)], -1).reshape(-1, 3)
    for i in range(6):
        eye = torch.tensor([-0.8 + 0.8 * (i % 3), -1.6, 0.9 + 0.6 * (i // 3)])
        c2w = _look_at(eye, torch.tensor([0.0, 0.8, 0.9]))
        dirs = (pix @ torch.linalg.inv(K_TEST).T) @ c2w[:3, :3].T
        origins = eye.expand_as(dirs)
        t, label, colour = _cast(origins, dirs)
        views.append({"c2w": c2w, "origins": origins, "dirs": dirs, "t": t, "label": label,
                      "rgb": colour})
    return views


@pytest.fixture
def one_thread() -> Iterator[None]:
    """Run on one intra-op thread: these small matmuls gain little from a second one, and on a
    busy 2-core machine the spinning second thread made a step 7x slower (measured)."""
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        yield
    finally:
        torch.set_num_threads(threads)


@pytest.mark.usefixtures("one_thread")
def test_overfit_one_analytic_scene_reaches_high_miou() -> None:
    torch.manual_seed(0)
    views = _room_views()
    depths = torch.cat([v["t"] for v in views])
    near, far = 0.8 * float(depths.min()), 1.1 * float(depths.max())
    c2ws = torch.stack([v["c2w"] for v in views])
    center, scale = scene_box_from_cameras(K_TEST, c2ws, (HEIGHT, WIDTH), near, far)
    cfg = SemanticNeRFConfig(n_classes=4, pos_freqs=6, dir_freqs=2, n_coarse=24, n_fine=24,
                             scene_center=center, scene_scale=scale, **SMALL)
    model = SemanticNeRF(cfg)
    origins = torch.cat([v["origins"] for v in views])
    dirs = torch.cat([v["dirs"] for v in views])
    labels = torch.cat([v["label"] for v in views])
    rgbs = torch.cat([v["rgb"] for v in views])
    opt = torch.optim.Adam(model.parameters(), lr=5e-3)
    gen = torch.Generator().manual_seed(0)
    start = time.perf_counter()
    for _ in range(250):
        idx = torch.randint(0, len(labels), (256,), generator=gen)
        out = model.render_rays(origins[idx], dirs[idx], near, far, stratified=True, generator=gen)
        loss, _ = render_loss(out, labels[idx], rgbs[idx], cfg)
        opt.zero_grad()
        loss.backward()
        opt.step()
    train_s = time.perf_counter() - start
    images = model.render_image(K_TEST, views[0]["c2w"], (HEIGHT, WIDTH), near, far, chunk=300)
    image = images["fine"]
    with torch.no_grad():  # the chunked image equals rendering this file's own rays at once
        direct = model.render_rays(views[0]["origins"], views[0]["dirs"], near, far, False)
    torch.testing.assert_close(image["logits"].reshape(-1, 4), direct["fine"]["logits"],
                               atol=1e-4, rtol=1e-4)
    pred = image["logits"].argmax(-1)
    metrics = scene_metrics(confusion_matrix(pred, views[0]["label"].reshape(HEIGHT, WIDTH), 4,
                                             cfg.ignore_id))
    print(f"overfit: {train_s:.1f} s for 250 steps, mIoU {metrics['miou']:.3f}")
    assert metrics["n_classes_present"] == 4
    assert metrics["miou"] > 0.9
    # Geometry is learnt too, at least coarsely: the box renders in front of the walls.
    label = views[0]["label"].reshape(HEIGHT, WIDTH)
    depth = image["depth"] / image["opacity"].clamp_min(1e-6)
    assert float(depth[label == 3].mean()) < float(depth[label == 1].mean()) - 0.5
