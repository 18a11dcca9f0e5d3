"""Render held-out query views of one scene and score them (validation, ``sray eval``, the fleet).

Every score names its protocol (``sray.model.metrics``): semantic scores both from one confusion
matrix per scene ("dataset-level") and per image ("per-image mean"); colour by PSNR, and by SSIM
on whole images only (a strided render has no SSIM: its pixels are not neighbours in the image).
LPIPS is not reported: its backbones are downloaded at run time, which this platform cannot do.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import torch
from torch import Tensor, nn

from sray.data_tools.loader.sample_types import EvalSample
from sray.model.fast_render import FastRender, upsample_to
from sray.model.metrics import confusion_matrix, per_image_miou, psnr, scene_metrics
from sray.model.ray_chunks import render_chunk_rays
from sray.model.semantic_ray import SourceSet
from sray.model.ssim import SSIM_WINDOW, ssim
from sray.platform.common.model_input import ray_batch

Renderer = Callable[[Tensor, Tensor, Tensor, Tensor], dict[str, dict[str, Tensor]]]
"""``render(origins (R, 3), dirs (R, 3), near (R,), far (R,)) -> {"coarse": pass, "fine": pass}``,
deterministic sampling."""


@dataclass
class ViewPrediction:
    """One rendered query view (on a strided pixel grid) next to its ground truth."""

    query_id: str
    pred_label: Tensor
    """int64 (h, w) argmax of the fine pass's rendered logits."""
    pred_rgb: Tensor
    """float32 (h, w, 3) fine-pass colour in [0, 1]."""
    gt_label: Tensor
    """int64 (h, w) ground truth (ignore id = unlabelled)."""
    gt_rgb: Tensor
    """float32 (h, w, 3) ground-truth colour."""
    stride: int
    """Every ``stride``-th pixel of the query image in each direction; 1 = the whole image."""


def strided_pixels(h: int, w: int, stride: int) -> tuple[Tensor, int, int]:
    """Pixel centres (u, v) of every ``stride``-th pixel: exact pixels of the full image, so labels
    and colours are read without resampling. Returns (uv (h'*w', 2), h', w')."""
    vs = torch.arange(stride // 2, h, stride, dtype=torch.float32)
    us = torch.arange(stride // 2, w, stride, dtype=torch.float32)
    v, u = torch.meshgrid(vs, us, indexing="ij")
    return torch.stack([u.reshape(-1), v.reshape(-1)], dim=-1), len(vs), len(us)


def fitted_pixel_stride(pixel_stride: int, stride: int, hw: tuple[int, int]) -> int:
    """The fast mode's pixel stride on an (h, w) image scored every ``stride``-th pixel: ``pixel_stride``,
    or the largest smaller one whose render grid still holds a ray in each direction (a small image or a
    large ``stride``: the grid's first pixel, ``stride * s // 2``, must lie inside the image)."""
    return max(1, min(pixel_stride, (2 * min(hw) - 1) // stride))  # stride * s // 2 < min(hw)


@torch.no_grad()
def render_in_chunks(render: Renderer, origins: Tensor, dirs: Tensor, near: Tensor, far: Tensor, chunk: int,
                     with_depth: bool = False) -> tuple[Tensor, ...]:
    """The fine pass of R rays (origins, dirs (R, 3); near, far (R,)) rendered ``chunk`` rays at a time (0: by
    device, ``ray_chunks``), on the host in float32: logits (R, L), colours (R, 3) clamped to [0, 1], and with
    ``with_depth`` the z-depth (R, 1)."""
    logits, colours, depths = [], [], []
    chunk = render_chunk_rays(chunk, origins.device)
    for start in range(0, origins.shape[0], chunk):
        sl = slice(start, start + chunk)
        fine = render(origins[sl], dirs[sl], near[sl], far[sl])["fine"]
        logits.append(fine["logits"].float().cpu())
        colours.append(fine["rgb"].float().clamp(0, 1).cpu())
        if with_depth:
            depths.append(fine["depth"].float().cpu())
    out = (torch.cat(logits), torch.cat(colours))
    return (*out, torch.cat(depths)[:, None]) if with_depth else out


@torch.no_grad()
def render_view(render: Renderer, sample: EvalSample, stride: int, chunk: int,
                device: torch.device, fast: FastRender | None = None) -> ViewPrediction:
    """Render one evaluation sample (whole query image, fixed source views) with ``render`` in ray
    chunks of at most ``chunk`` rays (0: by device, ``ray_chunks``), scored at every ``stride``-th pixel in
    each direction.

    With ``fast`` (the fast render mode; ``render`` must be ``sray_renderer(..., fast)``) the rays are
    every ``stride * fast.pixel_stride``-th pixel (fewer where the image is too small for that grid,
    :func:`fitted_pixel_stride`) and the logits and colours are upsampled bilinearly to the scored pixels.
    """
    gt_rgb, gt_label = sample.query_rgb, sample.query_label
    h, w = gt_label.shape
    uv, hh, ww = strided_pixels(h, w, stride)
    render_stride = stride * (fitted_pixel_stride(fast.pixel_stride, stride, (h, w)) if fast is not None else 1)
    uv_r, hr, wr = strided_pixels(h, w, render_stride)
    origins, dirs, near, far = ray_batch(sample, uv_r).query.to(device).rays()  # (R, 3), (R, 3), (R,), (R,)
    pred_logits, pred_rgb = render_in_chunks(render, origins, dirs, near, far, chunk)  # (R, L), (R, 3)
    if render_stride != stride:
        pred_logits = upsample_to(pred_logits.reshape(hr, wr, -1), (hr, wr), render_stride, uv)
        pred_rgb = upsample_to(pred_rgb.reshape(hr, wr, 3), (hr, wr), render_stride, uv)
    iu, iv = uv[:, 0].long(), uv[:, 1].long()
    return ViewPrediction(
        query_id=sample.query_id,
        pred_label=pred_logits.argmax(-1).reshape(hh, ww), pred_rgb=pred_rgb.reshape(hh, ww, 3),
        gt_label=gt_label[iv, iu].reshape(hh, ww).long(), gt_rgb=gt_rgb[iv, iu].reshape(hh, ww, 3).float(),
        stride=stride)


def encode_sources(net: nn.Module, sample: EvalSample, device: torch.device) -> SourceSet:
    """The sample's fixed source views, moved to ``device`` and encoded by the S-Ray ``net``."""
    sources = sample.sources.to(device)
    return net.encode(sources.rgb, sources.K, sources.c2w, sources.depth)


def sray_renderer(net: nn.Module, sample: EvalSample, device: torch.device,
                  fast: FastRender | None = None) -> Renderer:
    """Encode the sample's fixed source views once; return a ray renderer bound to them (the full
    render, or the fast mode's rays with ``fast``)."""
    return source_renderer(net, encode_sources(net, sample, device), fast)


def source_renderer(net: nn.Module, src: SourceSet, fast: FastRender | None = None) -> Renderer:
    """A ray renderer bound to already encoded sources: the full render (deterministic samples), or the
    fast mode's rays with ``fast``."""
    if fast is not None:
        return lambda o, d, near, far: net.render_rays_fast(src, o, d, near, far, fast.confidence)
    return lambda o, d, near, far: net.render_rays(src, o, d, near, far, stratified=False)


def class_ious(views: list[ViewPrediction], n_classes: int, ignore_id: int) -> list[float | None]:
    """Dataset-level IoU of each class over ``views`` (one confusion matrix), None for a class absent
    from their ground truth."""
    conf = sum(confusion_matrix(v.pred_label, v.gt_label, n_classes, ignore_id) for v in views)
    return [None if math.isnan(v) else float(v) for v in scene_metrics(conf)["iou_per_class"]]


def score_views(views: list[ViewPrediction], n_classes: int, ignore_id: int) -> dict[str, float]:
    """Scene scores: dataset-level and per-image semantic metrics, PSNR and SSIM (mean over views).

    Keys: ``miou``, ``total_acc``, ``class_avg_acc`` (dataset-level protocol), ``miou_per_image``
    (per-image protocol), ``psnr``, and ``ssim`` only when every view is a whole image (stride 1):
    a strided render never gets an SSIM. Whole images smaller than the SSIM window score NaN.
    """
    conf = sum(confusion_matrix(v.pred_label, v.gt_label, n_classes, ignore_id) for v in views)
    dataset = scene_metrics(conf)
    per_image = per_image_miou([v.pred_label for v in views], [v.gt_label for v in views], n_classes, ignore_id)
    psnrs = [psnr(v.pred_rgb, v.gt_rgb) for v in views]
    scores = {"miou": float(dataset["miou"]), "total_acc": float(dataset["total_acc"]),
              "class_avg_acc": float(dataset["class_avg_acc"]), "miou_per_image": float(per_image["miou"]),
              "psnr": sum(psnrs) / len(psnrs)}
    if all(v.stride == 1 for v in views):
        big = all(min(v.gt_label.shape) >= SSIM_WINDOW for v in views)
        ssims = [ssim(v.pred_rgb, v.gt_rgb) for v in views] if big else [float("nan")]
        scores["ssim"] = sum(ssims) / len(ssims)
    return scores
