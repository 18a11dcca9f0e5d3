"""The shard loader: rank/worker splits, exact epoch lengths, correct samples, fixed eval, lossless decode."""

from __future__ import annotations

from dataclasses import asdict
from pathlib import Path

import numpy as np
import pytest
import scene_fixtures
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from sray.data_tools.loader.sample_types import EvalSample, TrainSample
from sray.data_tools.loader.shard_loader import make_eval_samples, make_train_loader, slot_scenes, worker_batches
from sray.data_tools.loader.views import StoredView
from sray.data_tools.png import encode_png
from sray.data_tools.scene import source_pool
from sray.data_tools.scene_folder import read_scene
from sray.data_tools.shards.manifest import read_manifest
from sray.data_tools.shards.neighbours import Neighbours
from sray.data_tools.shards.writer import scene_neighbours, write_shards

TRAIN = ["a", "b", "c", "d", "e"]


@pytest.fixture(scope="module")
def data(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """(scenes, shards): five 6-view train scenes and one 10-view test scene, 4 views per shard."""
    root = tmp_path_factory.mktemp("loader")
    scenes = scene_fixtures.write_dataset(root / "scenes", [(s, 6, "train") for s in TRAIN] + [("unseen", 10, "test")])
    write_shards(scenes, root / "shards", views_per_shard=4, neighbours=8, progress=False)
    return scenes, root / "shards"


def _tensors(sample: EvalSample) -> dict:
    """Every tensor of a sample by field (nested fields as nested dicts)."""
    return {k: v for k, v in asdict(sample).items() if k not in ("scene", "query_id", "near", "far")}


def _loader(shards: Path, **kw: object) -> torch.utils.data.DataLoader:
    """A small training loader over the train scenes; keyword arguments override the defaults."""
    args = dict(n_source=2, top_k=3, rays_per_batch=16, batches_per_epoch=7, rank=0, world_size=1, num_workers=0,
                seed=5, scenes=TRAIN)
    args.update(kw)
    return make_train_loader(shards, **args)


def test_two_ranks_two_workers_disjoint_shards_same_batches(data: tuple[Path, Path]) -> None:
    """Ranks 0 and 1 of 2 (two DataLoader workers each) read disjoint shards and yield 7 batches, every epoch."""
    manifest = read_manifest(data[1])
    loaders = [_loader(data[1], rank=r, world_size=2, num_workers=2) for r in (0, 1)]
    for _ in range(2):  # two epochs
        drawn = [[s.scene for s in loader] for loader in loaders]
        assert [len(d) for d in drawn] == [7, 7] and [len(loader) for loader in loaders] == [7, 7]
        assert all(len(set(d)) >= 2 for d in drawn)  # the two workers of a rank read different scenes
        shards = [{sh for s in set(d) for sh in manifest.scenes[s].shards} for d in drawn]
        assert shards[0] and shards[1] and not shards[0] & shards[1]


def test_one_scene_two_ranks_get_disjoint_queries(data: tuple[Path, Path]) -> None:
    """With fewer scenes than slots, ranks share the scene but never a query view."""
    queries = [{s.query_id for s in _loader(data[1], scenes=["a"], rank=r, world_size=2, batches_per_epoch=12)}
               for r in (0, 1)]
    assert queries[0] and queries[1] and not queries[0] & queries[1]


@settings(max_examples=60, deadline=None)
@given(n_scenes=st.integers(1, 9), n_slots=st.integers(1, 9), pool=st.integers(1, 7), seed=st.integers(0, 99))
def test_slot_assignment_partitions_scenes_or_queries(n_scenes: int, n_slots: int, pool: int, seed: int) -> None:
    """Slots partition the scenes when there are enough, else partition each shared scene's queries."""
    scenes = [f"s{i}" for i in range(n_scenes)]
    pools = {s: [f"{s}v{j}" for j in range(pool)] for s in scenes}
    got = [slot_scenes(scenes, pools, slot, n_slots, np.random.default_rng(seed)) for slot in range(n_slots)]
    if n_scenes >= n_slots:
        names = [s for g in got for s, _ in g]
        assert sorted(names) == scenes and all(q == pools[s] for g in got for s, q in g)
        return
    for scene in scenes:
        shares = [q for g in got for s, q in g if s == scene]
        flat = [v for q in shares for v in q]
        assert shares and all(len(g) == 1 for g in got)
        if pool >= len(shares):
            assert sorted(flat) == sorted(pools[scene])


@given(batches=st.integers(1, 500), workers=st.integers(1, 8))
def test_worker_batches_sum_to_the_epoch(batches: int, workers: int) -> None:
    """Per-worker counts add up to exactly the rank's epoch length and differ by at most one."""
    counts = [worker_batches(batches, w, workers) for w in range(workers)]
    assert sum(counts) == batches and max(counts) - min(counts) <= 1


def test_training_samples_match_the_scenes(data: tuple[Path, Path]) -> None:
    """Targets are the query's pixels, sources are among its top-k pool neighbours, bounds are the scene's."""
    scenes_dir, shards = data
    loader = _loader(shards, scenes=["a", "unseen"], batches_per_epoch=8, rays_per_batch=50, n_source=3, top_k=4,
                     visit_samples=2)
    seen = set()
    for s in loader:
        assert isinstance(s, TrainSample)
        scene = read_scene(scenes_dir / s.scene)
        views = {v.view_id: v for v in scene.views()}
        ranked, _ = scene_neighbours(scene, k=4)
        query = views[s.query_id]
        assert s.query_id in source_pool(scene.meta)
        u, v = s.pixels.long().unbind(1)
        assert s.pixels.dtype == torch.float32 and s.pixels.shape == (50, 2)
        torch.testing.assert_close(s.target_label, torch.from_numpy(query.label[v, u].astype(np.int64)))
        torch.testing.assert_close(s.target_rgb, torch.from_numpy(query.rgb[v, u] / 255.0).float(),
                                   atol=1e-7, rtol=0)
        torch.testing.assert_close(s.query.c2w, torch.from_numpy(query.c2w).float())
        for i in range(3):
            match = [vid for vid, view in views.items()
                     if torch.equal(torch.from_numpy(view.c2w).float(), s.sources.c2w[i])]
            assert len(match) == 1 and match[0] in ranked[s.query_id].ids
            rgb = torch.from_numpy(views[match[0]].rgb).permute(2, 0, 1).float() / 255.0
            torch.testing.assert_close(s.sources.rgb[i], rgb, atol=1e-7, rtol=0)
        assert s.near == pytest.approx(scene.meta.near) and s.far == pytest.approx(scene.meta.far)
        seen.add(s.scene)
    assert seen == {"a", "unseen"}


def test_epochs_advance_and_set_epoch_replays(data: tuple[Path, Path]) -> None:
    """Each iteration is a new epoch; set_epoch(0) replays the first one exactly; scenes=None means the
    train-role scenes only (the unseen test scene never leaks into pretraining)."""
    loader = _loader(data[1], scenes=None, visit_samples=1, batches_per_epoch=12)

    def stream() -> list[tuple]:
        return [(s.scene, s.query_id, s.pixels.sum().item()) for s in loader]

    first, second = stream(), stream()
    assert first != second and {s for s, _, _ in first + second} <= set(TRAIN)
    assert len({s for s, _, _ in first + second}) >= 3
    loader.set_epoch(0)
    assert stream() == first


@pytest.mark.parametrize("scene,split,allowed", [("unseen", "test", "source"), ("b", "test", "train")])
def test_eval_samples_are_fixed_and_lossless(data: tuple[Path, Path], scene: str, split: str, allowed: str) -> None:
    """Eval yields each held-out view once, with the top-n ranked allowed sources, identically every call."""
    scenes_dir, shards = data
    canon = read_scene(scenes_dir / scene)
    views = {v.view_id: v for v in canon.views()}
    ranked, _ = scene_neighbours(canon, k=8)
    first, again = (list(make_eval_samples(shards, scene, split, n_source=2)) for _ in range(2))
    assert [s.query_id for s in first] == canon.meta.splits[split]
    for s, t in zip(first, again):
        assert isinstance(s, EvalSample)
        torch.testing.assert_close(_tensors(s), _tensors(t), atol=0, rtol=0)
        assert (s.scene, s.query_id, s.near, s.far) == (t.scene, t.query_id, t.near, t.far)
        q = views[s.query_id]
        torch.testing.assert_close(s.query_depth, torch.from_numpy(q.depth), atol=0, rtol=0)
        torch.testing.assert_close(s.query_label, torch.from_numpy(q.label.astype(np.int64)), atol=0, rtol=0)
        held_out = set(canon.meta.splits["test"])
        expected = [v for v in ranked[s.query_id].ids if v in canon.meta.splits[allowed] and v not in held_out][:2]
        torch.testing.assert_close(s.sources.c2w, torch.from_numpy(np.stack([views[v].c2w for v in expected])).float())
    with pytest.raises(ValueError, match="n_source"):
        make_eval_samples(shards, scene, split, n_source=9)


def test_16_bit_pngs_decode_without_loss() -> None:
    """Depth and labels spanning the full 16-bit range come back exactly (8-bit decoders would clip them)."""
    rng = np.random.default_rng(0)
    depth_mm = rng.integers(0, 65536, size=(30, 40), dtype=np.uint16)
    label = rng.integers(0, 65536, size=(30, 40), dtype=np.uint16)
    view = StoredView("v", encode_png(np.zeros((30, 40, 3), np.uint8)), encode_png(depth_mm), encode_png(label),
                      np.eye(3), np.eye(4), Neighbours([], []), "test")
    np.testing.assert_array_equal(view.label(), label)
    np.testing.assert_array_equal(view.depth(), depth_mm.astype(np.float32) / 1000.0)


def test_bad_arguments_are_refused(data: tuple[Path, Path]) -> None:
    """top_k above the stored neighbours, n_source above top_k, a bad rank or an unknown scene raise."""
    for kw, match in [(dict(top_k=9), "neighbours"), (dict(n_source=4), "n_source"), (dict(rank=2), "rank"),
                      (dict(scenes=["nope"]), "nope")]:
        with pytest.raises(ValueError, match=match):
            _loader(data[1], **kw)


def test_label_ids_outside_the_label_space_are_refused_on_the_host() -> None:
    """The loader checks target ids once per batch (the training step no longer reads them back)."""
    from sray.data_tools.loader.samples import check_label_ids

    check_label_ids(np.array([0, 19, 255, 3]), 20, "room", "v1")  # in range, ignore id allowed
    with pytest.raises(ValueError, match=r"scene 'room', view 'v7': label ids \[20, 40\]"):
        check_label_ids(np.array([0, 40, 20, 255]), 20, "room", "v7")
