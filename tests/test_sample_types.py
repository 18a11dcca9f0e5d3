"""Typed loader samples: the documented shapes and dtypes (checked against the views stored in the
shards), and what batching, worker processes, pinning and device moves do to them."""

from __future__ import annotations

from dataclasses import fields
from pathlib import Path

import numpy as np
import pytest
import torch
from torch.utils.data import DataLoader
from train_fixtures import tiny_shards  # noqa: F401

from sray.data_tools.loader.sample_types import EvalSample, TrainSample
from sray.data_tools.loader.shard_loader import make_eval_samples, make_train_loader
from sray.data_tools.loader.views import StoredView, read_scene_views
from sray.data_tools.shards.manifest import read_manifest

N_SOURCE, RAYS = 3, 50
TRAIN_SPEC = {"sources.rgb": (torch.float32, ("m", 3, "H", "W")), "sources.K": (torch.float32, ("m", 3, 3)),
              "sources.c2w": (torch.float32, ("m", 4, 4)), "sources.depth": (torch.float32, ("m", "H", "W")),
              "query.K": (torch.float32, (3, 3)),
              "query.c2w": (torch.float32, (4, 4)), "pixels": (torch.float32, ("R", 2)),
              "target_label": (torch.int64, ("R",)), "target_rgb": (torch.float32, ("R", 3))}
"""docs/CONTRACTS.md "Loader samples": dtype and shape of every tensor of a training sample."""
EVAL_SPEC = {k: v for k, v in TRAIN_SPEC.items() if k.split(".")[0] in ("sources", "query")} | {
    "query_rgb": (torch.float32, ("H", "W", 3)), "query_label": (torch.int64, ("H", "W")),
    "query_depth": (torch.float32, ("H", "W"))}
"""The same for an evaluation sample."""


def _flat(sample: object, prefix: str = "") -> dict[str, object]:
    """Every field of a (nested) sample by dotted name."""
    out: dict[str, object] = {}
    for f in fields(sample):
        value = getattr(sample, f.name)
        out |= _flat(value, f"{prefix}{f.name}.") if hasattr(value, "__dataclass_fields__") else {
            f"{prefix}{f.name}": value}
    return out


def _check_spec(sample: object, spec: dict, sizes: dict[str, int]) -> None:
    """Every tensor field has the spec's dtype and shape (symbols from ``sizes``); there are no others."""
    tensors = {k: v for k, v in _flat(sample).items() if torch.is_tensor(v)}
    assert tensors.keys() == spec.keys()
    for name, (dtype, shape) in spec.items():
        want = tuple(sizes[d] if isinstance(d, str) else d for d in shape)
        assert (tensors[name].dtype, tuple(tensors[name].shape)) == (dtype, want), name


def _as_float(a: np.ndarray) -> torch.Tensor:
    return torch.from_numpy(np.asarray(a, np.float32))


def _check_cameras(sample: TrainSample | EvalSample, views: dict[str, StoredView]) -> None:
    """Query camera = the stored query view's; each source = some stored view's camera and colours."""
    q = views[sample.query_id]
    torch.testing.assert_close(sample.query.K, _as_float(q.K), rtol=0, atol=0)
    torch.testing.assert_close(sample.query.c2w, _as_float(q.c2w), rtol=0, atol=0)
    for i in range(N_SOURCE):
        match = [v for v in views.values() if torch.equal(_as_float(v.c2w), sample.sources.c2w[i])]
        assert len(match) == 1 and match[0].view_id != sample.query_id
        torch.testing.assert_close(sample.sources.K[i], _as_float(match[0].K), rtol=0, atol=0)
        torch.testing.assert_close(sample.sources.rgb[i], _as_float(match[0].rgb()).permute(2, 0, 1) / 255.0,
                                   rtol=0, atol=1e-7)


def _train_loader(shards: Path, workers: int = 0, batches: int = 4) -> DataLoader:
    return make_train_loader(shards, n_source=N_SOURCE, top_k=4, rays_per_batch=RAYS, batches_per_epoch=batches,
                             rank=0, world_size=1, num_workers=workers, seed=1)


def test_training_samples_carry_the_documented_shapes_and_dtypes(tiny_shards: Path) -> None:
    """Shapes and dtypes as documented; targets are the stored query view's pixels; bounds are the
    scene's floats from the manifest."""
    manifest = read_manifest(tiny_shards)
    for sample in _train_loader(tiny_shards):
        assert isinstance(sample, TrainSample)
        views = read_scene_views(tiny_shards, manifest.scenes[sample.scene])
        q = views[sample.query_id]
        rgb, label = q.rgb(), q.label()
        h, w = label.shape
        _check_spec(sample, TRAIN_SPEC, {"m": N_SOURCE, "R": RAYS, "H": h, "W": w})
        _check_cameras(sample, views)
        u, v = sample.pixels.long().unbind(1)
        torch.testing.assert_close(sample.pixels, torch.stack([u, v], 1).float(), rtol=0, atol=0)  # pixel centres
        assert 0 <= int(u.min()) and int(u.max()) < w and 0 <= int(v.min()) and int(v.max()) < h
        torch.testing.assert_close(sample.target_label, torch.from_numpy(label[v, u].astype(np.int64)), rtol=0, atol=0)
        torch.testing.assert_close(sample.target_rgb, _as_float(rgb[v, u]) / 255.0, rtol=0, atol=1e-7)
        meta = manifest.scenes[sample.scene].meta
        assert type(sample.near) is float and (sample.near, sample.far) == (meta["near"], meta["far"])


def test_evaluation_samples_carry_the_documented_shapes_and_dtypes(tiny_shards: Path) -> None:
    """The whole stored query image, labels and depth, decoded without loss, next to the sources."""
    manifest = read_manifest(tiny_shards)
    scene = next(s for s, e in manifest.scenes.items() if e.meta["role"] == "test")
    views = read_scene_views(tiny_shards, manifest.scenes[scene])
    samples = list(make_eval_samples(tiny_shards, scene, "test", n_source=N_SOURCE))
    assert [s.query_id for s in samples] == manifest.scenes[scene].meta["splits"]["test"]
    for sample in samples:
        assert isinstance(sample, EvalSample)
        q = views[sample.query_id]
        h, w = q.label().shape
        _check_spec(sample, EVAL_SPEC, {"m": N_SOURCE, "H": h, "W": w})
        _check_cameras(sample, views)
        torch.testing.assert_close(sample.query_rgb, _as_float(q.rgb()) / 255.0, rtol=0, atol=1e-7)
        torch.testing.assert_close(sample.query_label, torch.from_numpy(q.label().astype(np.int64)), rtol=0, atol=0)
        torch.testing.assert_close(sample.query_depth, torch.from_numpy(q.depth()), rtol=0, atol=0)
        assert type(sample.far) is float and sample.far == manifest.scenes[scene].meta["far"]


def _same(a: TrainSample, b: TrainSample) -> None:
    """Equal type, host values and tensors (value, dtype and shape)."""
    assert type(a) is type(b)
    flat_a, flat_b = _flat(a), _flat(b)
    assert flat_a.keys() == flat_b.keys()
    for name, value in flat_a.items():
        if torch.is_tensor(value):
            torch.testing.assert_close(flat_b[name], value, rtol=0, atol=0, msg=name)
        else:
            assert flat_b[name] == value, name


def test_batching_and_worker_processes_preserve_samples(tiny_shards: Path) -> None:
    """A DataLoader with ``batch_size=None`` (the loader's collation) and two worker processes returns
    every sample as it was made; the training loader's own workers yield documented samples too."""
    made = list(_train_loader(tiny_shards))
    passed = list(DataLoader(made, batch_size=None, num_workers=2))
    assert len(passed) == len(made)
    for a, b in zip(made, passed):
        _same(a, b)
    for sample in _train_loader(tiny_shards, workers=2, batches=3):
        assert isinstance(sample, TrainSample)
        h, w = sample.sources.rgb.shape[-2:]
        _check_spec(sample, TRAIN_SPEC, {"m": N_SOURCE, "R": RAYS, "H": h, "W": w})


def test_to_moves_every_tensor_and_keeps_host_values(tiny_shards: Path) -> None:
    """``.to(device)`` returns a moved copy (nested tensors too); names and bounds stay; the original stays."""
    sample = next(iter(_train_loader(tiny_shards, batches=1)))
    moved = sample.to("meta")
    assert type(moved) is TrainSample and type(moved.sources) is type(sample.sources)
    for name, value in _flat(moved).items():
        original = _flat(sample)[name]
        if torch.is_tensor(value):
            assert value.device.type == "meta" and original.device.type == "cpu", name
            assert (value.dtype, value.shape) == (original.dtype, original.shape), name
        else:
            assert value == original, name


@pytest.mark.gpu
def test_pinned_samples_copy_to_the_gpu_unchanged(tiny_shards: Path) -> None:
    """``DataLoader(pin_memory=True)`` pins every tensor of a sample; a non-blocking copy keeps the values."""
    loader = make_train_loader(tiny_shards, n_source=N_SOURCE, top_k=4, rays_per_batch=RAYS, batches_per_epoch=2,
                               rank=0, world_size=1, num_workers=0, seed=1, pin_memory=True)
    for sample in loader:
        assert all(v.is_pinned() for v in _flat(sample).values() if torch.is_tensor(v))
        on_gpu = sample.to("cuda", non_blocking=True)
        torch.cuda.synchronize()
        _same(sample, on_gpu.to("cpu"))
