"""The one whole-view renderer (``sray.model.view_render``) against independent computations.

* held-out views (``predict_view``, what ``sray eval``, validation, the fleet, the stability suite and the
  speed-accuracy bench score) equal, bit for bit, a naive loop kept here: the rays of the scored (or the fast
  mode's sparser) pixel grid built by the loader-to-model conversion, rendered chunk by chunk, the fine pass
  moved to the host, colours clamped, then upsampled;
* ``render_image`` equals one ``render_rays`` call over the pixels it renders (every pixel, every other one),
  within float32 rounding, for S-Ray and Semantic-NeRF;
* the fast mode's strided + upsampled maps equal its rays rendered at the grid's pixels and interpolated
  bilinearly by hand in float64 (border pixels take the nearest grid row or column).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch
from fleet_fixtures import tiny_checkpoint  # noqa: F401
from test_model_sray import FAR, NEAR, H, K, W, model, rig
from torch import Tensor
from train_fixtures import tiny_shards  # noqa: F401

from sray.data_tools.loader.sample_types import EvalSample
from sray.data_tools.loader.shard_loader import make_eval_samples
from sray.model.fast_render import FastRender, upsample_to
from sray.model.rays import image_pixels, pixel_rays
from sray.model.runtime import Runtime
from sray.model.semantic_nerf import SemanticNeRF, SemanticNeRFConfig
from sray.model.view_render import RayRenderer
from sray.platform.checkpoints.model_loading import model_from_checkpoint
from sray.platform.common.model_input import ray_batch
from sray.platform.eval.view_scoring import predict_view, sray_renderer

CPU = torch.device("cpu")


def _grid(h: int, w: int, stride: int) -> tuple[Tensor, int, int]:
    """Pixel centres (u, v) of every ``stride``-th pixel from (stride // 2, stride // 2), row-major."""
    vs, us = np.arange(stride // 2, h, stride), np.arange(stride // 2, w, stride)
    v, u = np.meshgrid(vs, us, indexing="ij")
    return torch.from_numpy(np.stack([u.ravel(), v.ravel()], -1).astype(np.float32)), len(vs), len(us)


@torch.no_grad()
def naive_view(render: RayRenderer, sample: EvalSample, stride: int, chunk: int,
               fast: FastRender | None) -> tuple[Tensor, Tensor]:
    """(labels (h', w'), colours (h', w', 3)) of a held-out view, the long way round (module doc)."""
    h, w = sample.query_label.shape
    uv, hh, ww = _grid(h, w, stride)
    ray_stride = stride * (max(1, min(fast.pixel_stride, (2 * min(h, w) - 1) // stride)) if fast else 1)
    uv_r, hr, wr = _grid(h, w, ray_stride)
    origins, dirs, near, far = ray_batch(sample, uv_r).query.rays()
    logits, colours = [], []
    for start in range(0, len(uv_r), chunk):
        fine = render(origins[start:start + chunk], dirs[start:start + chunk], near[start:start + chunk],
                      far[start:start + chunk])["fine"]
        logits.append(fine["logits"].float().cpu())
        colours.append(fine["rgb"].float().clamp(0, 1).cpu())
    logits, colours = torch.cat(logits), torch.cat(colours)
    if ray_stride != stride:
        logits = upsample_to(logits.reshape(hr, wr, -1), (hr, wr), ray_stride, uv)
        colours = upsample_to(colours.reshape(hr, wr, 3), (hr, wr), ray_stride, uv)
    return logits.argmax(-1).reshape(hh, ww), colours.reshape(hh, ww, 3)


@pytest.mark.parametrize(("stride", "fast"), [(1, None), (3, None), (1, FastRender(4, 0.9)), (2, FastRender(3, 0.5)),
                                              (8, FastRender(8, 0.9))],
                         ids=["full-s1", "full-s3", "fast4-s1", "fast3-s2", "fast8-s8 (fitted to 7)"])
def test_held_out_views_equal_the_naive_loop_bit_for_bit(tiny_checkpoint: Path, tiny_shards: Path, stride: int,
                                                        fast: FastRender | None) -> None:
    net, _ = model_from_checkpoint(tiny_checkpoint)
    sample = next(iter(make_eval_samples(tiny_shards, "synth_test_000", split="test", n_source=3)))
    render = sray_renderer(net.eval(), sample, CPU, fast)
    view = predict_view(render, sample, stride, 97, CPU, fast)
    labels, colours = naive_view(render, sample, stride, 97, fast)
    assert view.pred_label.shape == labels.shape and view.stride == stride
    assert torch.equal(view.pred_label, labels)
    assert torch.equal(view.pred_rgb, colours)


def _one_pass(render: RayRenderer, uv: Tensor, c2w: Tensor) -> dict[str, dict[str, Tensor]]:
    """Every ray of ``uv`` in one call of ``render``."""
    origins, dirs = pixel_rays(K, c2w, uv)
    n = len(uv)
    with torch.no_grad():
        return render(origins, dirs, torch.full((n,), NEAR), torch.full((n,), FAR))


def _close_to_one_pass(image: dict[str, dict[str, Tensor]], rays: dict[str, dict[str, Tensor]], hw: tuple) -> None:
    for p in ("coarse", "fine"):
        for key, value in image[p].items():
            want = rays[p][key].clamp(0, 1) if key == "rgb" else rays[p][key]
            assert value.shape[:2] == hw and value.dtype == torch.float32
            torch.testing.assert_close(value.reshape(want.shape), want, rtol=1e-5, atol=1e-5, msg=f"{p}/{key}")


def test_sray_render_image_equals_one_pass_over_its_pixels() -> None:
    """Every other pixel (the whole image in chunks: ``tests/test_model_sray.py``)."""
    net, r = model(), rig(m=3)
    src = net.encode(r["rgb"], r["K"], r["c2w"])
    image = net.render_image(src, K, r["query"], (H, W), NEAR, FAR, Runtime(chunk=97), stride=2)
    uv, hh, ww = _grid(H, W, 2)
    _close_to_one_pass(image, _one_pass(net.ray_renderer(src), uv, r["query"]), (hh, ww))


def test_semantic_nerf_render_image_equals_one_pass_over_every_pixel() -> None:
    torch.manual_seed(0)
    net = SemanticNeRF(SemanticNeRFConfig(n_classes=4, n_coarse=8, n_fine=8, width=32, depth=2, skip_layer=1,
                                          color_width=16, semantic_width=16)).eval()
    c2w = rig(m=1)["query"]
    image = net.render_image(K, c2w, (H, W), NEAR, FAR, chunk=101)
    rays = _one_pass(lambda o, d, lo, hi: net.render_rays(o, d, lo, hi, stratified=False), image_pixels(H, W), c2w)
    _close_to_one_pass(image, rays, (H, W))


def _bilinear_by_hand(grid: np.ndarray, us: np.ndarray, vs: np.ndarray, h: int, w: int) -> np.ndarray:
    """(h, w, D) values at every pixel from ``grid`` (h', w', D) at pixel columns ``us``, rows ``vs``, float64;
    outside the grid the nearest row or column."""
    out = np.empty((h, w, grid.shape[-1]))
    for v in range(h):
        i = int(np.clip(np.searchsorted(vs, v, side="right") - 1, 0, len(vs) - 2))
        fy = float(np.clip((v - vs[i]) / (vs[i + 1] - vs[i]), 0, 1))
        for u in range(w):
            j = int(np.clip(np.searchsorted(us, u, side="right") - 1, 0, len(us) - 2))
            fx = float(np.clip((u - us[j]) / (us[j + 1] - us[j]), 0, 1))
            out[v, u] = ((1 - fy) * ((1 - fx) * grid[i, j] + fx * grid[i, j + 1])
                         + fy * ((1 - fx) * grid[i + 1, j] + fx * grid[i + 1, j + 1]))
    return out


def test_the_fast_mode_upsamples_its_own_strided_rays() -> None:
    """Pixel stride 3 on 32x40: grid rows 1..31, columns 1..37, so the last two columns lie past the grid."""
    pixel_stride = 3
    net, r = model(fine_samples="new"), rig(m=3)
    src = net.encode(r["rgb"], r["K"], r["c2w"])
    fast = FastRender(pixel_stride, confidence=0.5)
    image = net.render_image(src, K, r["query"], (H, W), NEAR, FAR, Runtime(chunk=50), fast=fast)
    uv, hh, ww = _grid(H, W, pixel_stride)
    rays = _one_pass(net.ray_renderer(src, fast), uv, r["query"])
    vs = np.arange(pixel_stride // 2, H, pixel_stride, dtype=np.float64)
    us = np.arange(pixel_stride // 2, W, pixel_stride, dtype=np.float64)
    for p in ("coarse", "fine"):
        for key, value in image[p].items():
            grid = rays[p][key].clamp(0, 1) if key == "rgb" else rays[p][key]
            want = _bilinear_by_hand(grid.double().reshape(hh, ww, -1).numpy(), us, vs, H, W)
            assert value.shape[:2] == (H, W)
            np.testing.assert_allclose(value.reshape(H, W, -1).double().numpy(), want, rtol=1e-5, atol=1e-5,
                                       err_msg=f"{p}/{key}")
