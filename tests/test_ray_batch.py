"""The model surface (``sray.model.ray_batch``) against the bare network, and the platform's one
conversion from a loader sample to it (``sray.platform.common.model_input.ray_batch``)."""

from __future__ import annotations

import pytest
import torch

from sray.data_tools.loader.sample_types import EvalSample, QueryCamera, SourceViews, TrainSample
from sray.model.config import SRayConfig
from sray.model.losses import render_loss
from sray.model.ray_batch import QueryRays, RayBatch, RayBatchLoss
from sray.model.rays import pixel_rays
from sray.model.runtime import Runtime
from sray.platform.common.model_input import ray_batch

H, W, M, R, NEAR, FAR = 32, 40, 3, 40, 1.2, 4.5
TOL = dict(rtol=1e-6, atol=1e-6)
"""Both sides run the same float32 kernels; only the bounds' memory layout differs (filled vs expanded)."""


def _sample(seed: int = 0) -> TrainSample:
    """Three sources beside a query camera at the origin, all looking down +z; R random pixels."""
    g = torch.Generator().manual_seed(seed)
    K = torch.tensor([[28.0, 0.0, (W - 1) / 2], [0.0, 28.0, (H - 1) / 2], [0.0, 0.0, 1.0]])
    c2w = torch.eye(4).repeat(M, 1, 1)
    c2w[:, 0, 3] = torch.tensor([-0.3, 0.1, 0.3])
    query_c2w = torch.eye(4)
    query_c2w[:3, 3] = torch.tensor([0.05, -0.02, 0.0])
    sources = SourceViews(rgb=torch.rand(M, 3, H, W, generator=g), K=K.expand(M, 3, 3).clone(), c2w=c2w)
    return TrainSample(scene="s", query_id="q", sources=sources, query=QueryCamera(K=K, c2w=query_c2w),
                       near=NEAR, far=FAR, pixels=torch.rand(R, 2, generator=g) * torch.tensor([W - 1.0, H - 1.0]),
                       target_label=torch.randint(0, 5, (R,), generator=g), target_rgb=torch.rand(R, 3, generator=g))


def _surface() -> RayBatchLoss:
    torch.manual_seed(0)
    return RayBatchLoss(SRayConfig(n_classes=5, feat_dim=8, n_coarse=6, n_fine=6, n_source=M), Runtime(train_piece=R))


def _direct(model: RayBatchLoss, sample: TrainSample) -> tuple[torch.Tensor, dict]:
    """The bare network's own calls: encode, ``pixel_rays``, the scalar bounds expanded by ``render_rays``
    (stratified samples), and ``render_loss``."""
    net = model.net
    src = net.encode(sample.sources.rgb, sample.sources.K, sample.sources.c2w)
    origins, dirs = pixel_rays(sample.query.K, sample.query.c2w, sample.pixels)
    out = net.render_rays(src, origins, dirs, sample.near, sample.far, stratified=True)
    return render_loss(out, sample.target_label, sample.target_rgb, net.cfg)


def test_the_surface_computes_the_loss_of_encode_render_rays_and_render_loss() -> None:
    """One piece (``train_piece`` = the batch), same seed: the loss, its terms and every parameter's
    gradient match the bare network's calls (pieces of fewer rays: tests/test_piecewise_loss.py)."""
    model, sample = _surface(), _sample()
    results = []
    for compute in (lambda: model(ray_batch(sample), sample.target_label, sample.target_rgb),
                    lambda: _direct(model, sample)):
        model.zero_grad()
        torch.manual_seed(7)
        loss, terms = compute()
        loss.backward()
        results.append((loss.detach(), terms, {n: q.grad.clone() for n, q in model.named_parameters()
                                                if q.grad is not None}))
    (loss_got, terms_got, grads_got), (loss_want, terms_want, grads_want) = results
    torch.testing.assert_close(loss_got, loss_want, **TOL)
    torch.testing.assert_close(terms_got, terms_want, **TOL)
    assert grads_got.keys() == grads_want.keys() and any(k.startswith("net.encoder.") for k in grads_got)
    torch.testing.assert_close(grads_got, grads_want, rtol=1e-5, atol=1e-6)


def test_query_rays_are_pixel_rays_with_per_ray_bounds() -> None:
    """``QueryRays.rays``: the rays of ``pixel_rays`` and the scalar bounds as float32 (R,) tensors."""
    sample = _sample(1)
    origins, dirs, near, far = QueryRays(sample.query.K, sample.query.c2w, sample.pixels, NEAR, FAR).rays()
    ref_o, ref_d = pixel_rays(sample.query.K, sample.query.c2w, sample.pixels)
    torch.testing.assert_close((origins, dirs), (ref_o, ref_d), rtol=0, atol=0)
    assert near.dtype == far.dtype == torch.float32 and near.shape == far.shape == (R,)
    assert near.tolist() == [torch.tensor(NEAR).item()] * R and far.tolist() == [torch.tensor(FAR).item()] * R


def test_ray_batch_shares_the_sample_tensors_and_needs_pixels_for_an_eval_sample() -> None:
    """The platform's conversion copies nothing; an evaluation sample renders the pixels it is given."""
    sample = _sample()
    batch = ray_batch(sample)
    assert isinstance(batch, RayBatch)
    assert batch.src_rgb is sample.sources.rgb and batch.src_K is sample.sources.K
    assert batch.src_c2w is sample.sources.c2w and batch.query.pixels is sample.pixels
    assert batch.query.K is sample.query.K and batch.query.c2w is sample.query.c2w
    assert (batch.query.near, batch.query.far) == (NEAR, FAR)
    full = EvalSample(scene="s", query_id="q", sources=sample.sources, query=sample.query, near=NEAR, far=FAR,
                      query_rgb=torch.zeros(H, W, 3), query_label=torch.zeros(H, W, dtype=torch.int64),
                      query_depth=torch.zeros(H, W))
    with pytest.raises(ValueError, match="has no pixels"):
        ray_batch(full)
    grid = torch.tensor([[0.0, 0.0], [W - 1.0, H - 1.0]])
    assert ray_batch(full, grid).query.pixels is grid
