"""Training augmentation: off = the plain sample, bit for bit; on = exact geometry, per-view colour, ranges."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import scene_fixtures
import torch

from sray.data_tools.loader.augment import Augmentation, rescale_view
from sray.data_tools.loader.samples import train_sample
from sray.data_tools.loader.shard_loader import make_train_loader
from sray.data_tools.loader.views import read_scene_views
from sray.data_tools.shards.manifest import read_manifest
from sray.data_tools.shards.writer import write_shards
from sray.jobs.cli import build_parser
from sray.jobs.train_cmd import build_config
from sray.platform.config.train_config import TrainConfig
from sray.platform.train.job_loader import job_loader


@pytest.fixture(scope="module")
def shards(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Two 12-view train scenes of 30x40 pixels, 10 ranked neighbours per view."""
    root = tmp_path_factory.mktemp("augment")
    scenes = scene_fixtures.write_dataset(root / "scenes", [("a", 12, "train"), ("b", 12, "train")])
    write_shards(scenes, root / "shards", views_per_shard=6, neighbours=10, progress=False)
    return root / "shards"


@pytest.fixture(scope="module")
def views(shards: Path) -> dict:
    """Scene a's stored views."""
    return read_scene_views(shards, read_manifest(shards).scenes["a"])


def _draw(views: dict, augment: Augmentation | None, seed: int = 3, n_rays: int = 50):
    ids = sorted(views)
    return train_sample(views, ids[0], ids[1:5], n_rays, np.random.default_rng(seed), "a", 0.5, 6.0, 20, augment)


def test_everything_off_is_the_plain_sample_drawn_independently(views: dict) -> None:
    """The sample with no augmentation equals one assembled here by the documented rule."""
    ids = sorted(views)
    for augment in (None, Augmentation()):
        sample = _draw(views, augment)
        rng = np.random.default_rng(3)
        label, rgb = views[ids[0]].label(), views[ids[0]].rgb()
        flat = rng.choice(label.size, size=50, replace=False)
        v, u = flat // label.shape[1], flat % label.shape[1]
        assert torch.equal(sample.pixels, torch.from_numpy(np.stack([u, v], 1).astype(np.float32)))
        assert torch.equal(sample.target_label, torch.from_numpy(label[v, u].astype(np.int64)))
        assert torch.equal(sample.target_rgb, torch.from_numpy(rgb[v, u].astype(np.float32) / 255.0))
        src = np.stack([views[s].rgb() for s in ids[1:5]]).astype(np.float32) / 255.0
        assert torch.equal(sample.sources.rgb, torch.from_numpy(src).permute(0, 3, 1, 2))
        assert torch.equal(sample.sources.K, torch.from_numpy(np.stack([views[s].K for s in ids[1:5]])).float())


def test_loader_with_augmentation_off_yields_identical_batches(shards: Path) -> None:
    kwargs = dict(n_source=3, top_k=6, rays_per_batch=32, batches_per_epoch=6, rank=0, world_size=1,
                  num_workers=0, seed=5)
    plain, off = list(make_train_loader(shards, **kwargs)), list(make_train_loader(shards, augment=Augmentation(),
                                                                                   **kwargs))
    for a, b in zip(plain, off, strict=True):
        assert a.query_id == b.query_id
        for x, y in ((a.pixels, b.pixels), (a.sources.rgb, b.sources.rgb), (a.sources.c2w, b.sources.c2w)):
            assert torch.equal(x, y)


def test_set_data_aug_reaches_the_training_loader(shards: Path) -> None:
    """``sray train --set data.aug.<field>=...`` -> the config the workers receive -> a rank's loader."""
    args = build_parser().parse_args(["train", "--data", str(shards), "--set", "data.aug.colour_ev=0.3",
                                      "--set", "data.aug.min_source=2", "--set", "model.n_source=3"])
    payload = json.loads(json.dumps(build_config(args).to_dict()))  # as the launcher hands it to the workers
    loader = job_loader(TrainConfig.from_dict(payload), rank=0, world_size=1, batches_per_epoch=2)
    assert loader.dataset.augment == Augmentation(colour_ev=0.3, min_source=2)


@pytest.mark.parametrize("scale", [0.5, 0.63, 0.8])
def test_rescaled_intrinsics_follow_the_resized_pixels(scale: float) -> None:
    """A ramp image holds each pixel's own centre coordinate; the resize (a symmetric prefilter, then
    bilinear) keeps a linear ramp exact away from the borders, so the value at a point's projection
    with the new K must be its projection with the old K."""
    h, w = 60, 80
    u, v = np.meshgrid(np.arange(w, dtype=np.float32), np.arange(h, dtype=np.float32))
    K = np.array([[70.0, 0.0, 39.5], [0.0, 72.0, 29.5], [0.0, 0.0, 1.0]])
    _, K2 = rescale_view(np.zeros((h, w, 3), np.uint8), K, scale)
    ramp_u = rescale_view(np.repeat(u[..., None], 3, 2), K, scale)[0][..., 0]
    ramp_v = rescale_view(np.repeat(v[..., None], 3, 2), K, scale)[0][..., 0]
    rng = np.random.default_rng(0)
    points = np.stack([rng.uniform(-0.3, 0.3, 200), rng.uniform(-0.2, 0.2, 200), rng.uniform(1, 3, 200)], 1)
    old, new = points @ K.T, points @ K2.T
    old, new = old[:, :2] / old[:, 2:], new[:, :2] / new[:, 2:]
    inside = np.all((new >= 4) & (new <= np.array(ramp_u.shape[::-1]) - 5), axis=1)
    ui, vi = np.rint(new[inside]).astype(int).T
    # the ramp at the nearest new pixel centre, moved back by the sub-pixel offset (the ramp's slope is 1/scale)
    u_back = ramp_u[vi, ui] + (new[inside, 0] - ui) * w / ramp_u.shape[1]
    v_back = ramp_v[vi, ui] + (new[inside, 1] - vi) * h / ramp_u.shape[0]
    torch.testing.assert_close(torch.from_numpy(u_back), torch.from_numpy(old[inside, 0]), rtol=0, atol=1e-3)
    torch.testing.assert_close(torch.from_numpy(v_back), torch.from_numpy(old[inside, 1]), rtol=0, atol=1e-3)


def test_colour_jitter_changes_each_source_alone_and_never_the_targets(views: dict) -> None:
    plain, jittered = _draw(views, None), _draw(views, Augmentation(colour_ev=0.7, channel_ev=0.2))
    for x, y in ((plain.pixels, jittered.pixels), (plain.target_rgb, jittered.target_rgb),
                 (plain.sources.K, jittered.sources.K), (plain.sources.c2w, jittered.sources.c2w)):
        assert torch.equal(x, y)
    ratios = []
    for i in range(4):
        a, b = plain.sources.rgb[i], jittered.sources.rgb[i]
        ok = (a > 0.05) & (b > 0.02) & (b < 0.98)                     # unclipped pixels: b = a * 2^(ev + gain_c)
        assert int(ok.sum()) > 100
        ratio = float(b[ok].sum() / a[ok].sum())
        assert 2 ** -0.95 < ratio < 2 ** 0.95
        ratios.append(ratio)
    assert len({round(r, 2) for r in ratios}) == 4, "every source view draws its own exposure"


def test_source_count_subsets_and_resolution_vary_inside_their_ranges(shards: Path) -> None:
    aug = Augmentation(min_source=2, source_scale=0.5)
    loader = make_train_loader(shards, n_source=6, top_k=8, rays_per_batch=16, batches_per_epoch=60, rank=0,
                               world_size=1, num_workers=0, seed=1, augment=aug)
    counts, widths = set(), set()
    for sample in loader:
        m = sample.sources.rgb.shape[0]
        assert 2 <= m <= 6 and sample.sources.K.shape == (m, 3, 3)
        counts.add(m)
        h, w = sample.sources.rgb.shape[2:]
        assert 15 <= h <= 30 and 20 <= w <= 40
        widths.add(w)
        cx = (w / 40) * (float(scene_fixtures.intrinsics(30, 40)[0, 2]) + 0.5) - 0.5   # the pixel-centre rule
        torch.testing.assert_close(sample.sources.K[:, 0, 2], torch.full((m,), cx), rtol=0, atol=1e-4)
    assert counts == set(range(2, 7)) and len(widths) > 5


def test_bad_settings_name_the_field() -> None:
    with pytest.raises(ValueError, match="source_scale"):
        Augmentation(source_scale=1.0)


def test_query_pixels_are_distinct_pixels_of_the_image_with_their_labels(views: dict) -> None:
    """The query pixels are distinct pixels inside the image, and their targets are the labels there."""
    ids = sorted(views)
    label = views[ids[0]].label()
    for seed in range(10):
        sample = train_sample(views, ids[0], ids[1:3], 40, np.random.default_rng(seed), "a", 0.5, 6.0, 20)
        u, v = sample.pixels[:, 0].long().numpy(), sample.pixels[:, 1].long().numpy()
        assert len(set(zip(u.tolist(), v.tolist()))) == 40
        assert (v >= 0).all() and (v < label.shape[0]).all() and (u >= 0).all() and (u < label.shape[1]).all()
        assert torch.equal(sample.target_label, torch.from_numpy(label[v, u].astype(np.int64)))
