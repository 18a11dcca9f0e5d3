"""The shard loader (docs/data.md, "The loader"): resampled training samples with a fixed epoch length per rank
(scenes are the unit split over ranks and DataLoader workers), fixed evaluation samples. Never pass these loaders
through ``accelerator.prepare``: it re-shards iterable datasets and drops samples."""

from __future__ import annotations

from collections.abc import Iterator
from functools import lru_cache
from pathlib import Path

import numpy as np
from torch.utils.data import DataLoader, IterableDataset, get_worker_info

from sray.data_tools.loader.augment import Augmentation
from sray.data_tools.loader.sample_types import EvalSample, TrainSample
from sray.data_tools.loader.samples import eval_sample, ranked_candidates, train_sample
from sray.data_tools.loader.views import read_scene_views
from sray.data_tools.scene import SceneMeta, source_pool
from sray.data_tools.shards.manifest import Manifest, read_manifest, verify_shards


def slot_scenes(scenes: list[str], pools: dict[str, list[str]], slot: int, n_slots: int,
                shared_rng: np.random.Generator) -> list[tuple[str, list[str]]]:
    """The (scene, query view ids) of a slot this epoch; ``shared_rng`` (same seed in every slot) orders the scenes."""
    order = [scenes[i] for i in shared_rng.permutation(len(scenes))]
    if len(order) >= n_slots:
        return [(s, pools[s]) for s in order[slot::n_slots]]
    scene = order[slot % len(order)]
    sharers = list(range(slot % len(order), n_slots, len(order)))
    queries = pools[scene][sharers.index(slot)::len(sharers)]
    return [(scene, queries or pools[scene])]


def worker_batches(batches_per_epoch: int, worker: int, num_workers: int) -> int:
    """Samples worker ``worker`` of ``num_workers`` yields so that the rank's total is exact."""
    return batches_per_epoch // num_workers + (1 if worker < batches_per_epoch % num_workers else 0)


class TrainTuples(IterableDataset):
    """Resampled training samples of one rank; length = batches per epoch."""

    def __init__(self, shards_dir: Path, manifest: Manifest, scenes: list[str], *, n_source: int, top_k: int,
                 rays_per_batch: int, batches_per_epoch: int, rank: int, world_size: int, seed: int,
                 cache_scenes: int, visit_samples: int, augment: Augmentation | None = None,
                 source_labels: bool = False) -> None:
        self.shards_dir, self.manifest, self.scenes = Path(shards_dir), manifest, scenes
        self.metas = {s: SceneMeta.from_json(manifest.scenes[s].meta) for s in scenes}
        self.pools = {s: source_pool(m) for s, m in self.metas.items()}
        self.n_source, self.top_k, self.rays = n_source, top_k, rays_per_batch
        self.batches, self.rank, self.world_size, self.seed = batches_per_epoch, rank, world_size, seed
        self.cache_scenes, self.visit_samples = cache_scenes, visit_samples
        self.augment = augment or Augmentation()
        self.source_labels = source_labels
        """Whether samples carry their source views' class ids (the source-view semantic loss)."""
        self.epoch = 0
        """Epoch whose random stream the next ``iter()`` produces."""

    def __len__(self) -> int:
        """Samples per epoch of this rank (all its workers together)."""
        return self.batches

    def __iter__(self) -> Iterator[TrainSample]:
        """This worker's share of the current epoch (the whole epoch when there are no workers)."""
        info = get_worker_info()
        worker, n_workers = (info.id, info.num_workers) if info else (0, 1)
        return self._generate(self.epoch, worker, n_workers)  # epoch read now, not when first consumed

    def _generate(self, epoch: int, worker: int, n_workers: int) -> Iterator[TrainSample]:
        slot, n_slots = self.rank * n_workers + worker, self.world_size * n_workers
        assigned = slot_scenes(self.scenes, self.pools, slot, n_slots, np.random.default_rng([self.seed, epoch]))
        rng = np.random.default_rng([self.seed, epoch, self.rank, worker, 1])
        cache = lru_cache(self.cache_scenes)(lambda s: read_scene_views(self.shards_dir, self.manifest.scenes[s]))
        remaining = worker_batches(self.batches, worker, n_workers)
        while remaining > 0:
            scene, queries = assigned[rng.integers(len(assigned))]
            views, meta = cache(scene), self.metas[scene]
            allowed = set(self.pools[scene])
            for _ in range(min(self.visit_samples, remaining)):
                query_id = queries[rng.integers(len(queries))]
                candidates = ranked_candidates(views[query_id], allowed, self.top_k)
                if len(candidates) < self.n_source:
                    raise ValueError(f"scene {scene!r}, view {query_id!r}: {len(candidates)} ranked neighbours, "
                                     f"n_source={self.n_source} needed; re-shard with a larger --neighbours")
                sources = [candidates[i] for i in self.augment.source_choice(rng, len(candidates), self.n_source)]
                yield train_sample(views, query_id, sources, self.rays, rng, scene, meta.near, meta.far,
                                   len(meta.class_names), self.augment, self.source_labels)
                remaining -= 1


class EpochLoader(DataLoader):
    """A DataLoader over :class:`TrainTuples` where each ``iter()`` starts the next epoch."""

    def set_epoch(self, epoch: int) -> None:
        """Make the next ``iter(loader)`` produce epoch ``epoch``'s random stream (e.g. after a resume)."""
        self.dataset.epoch = epoch

    def __iter__(self) -> Iterator[TrainSample]:
        """Iterate one epoch, then advance the epoch counter."""
        iterator = super().__iter__()  # workers have copied the dataset (and its epoch) by now
        self.dataset.epoch += 1
        return iterator


def _open(shards_dir: Path, scenes: list[str] | None,
          manifest: Manifest | None = None) -> tuple[Manifest, list[str]]:
    """The manifest (read and size-checked unless the caller passes it) and the scene list (None = train scenes)."""
    if manifest is None:
        problems = verify_shards(shards_dir, checksums=False)
        if problems:
            raise ValueError("the shard folder is damaged:\n  " + "\n  ".join(problems))
        manifest = read_manifest(shards_dir)
    if scenes is None:
        names = sorted(s for s, e in manifest.scenes.items() if e.meta.get("role", "train") == "train")
        if not names:
            raise ValueError(f"{shards_dir}/manifest.json: no scene has role 'train'; pass scenes=[...] "
                             f"explicitly (known: {sorted(manifest.scenes)[:10]})")
    else:
        names = list(scenes)
        unknown = [s for s in names if s not in manifest.scenes]
        if unknown or not names:
            raise ValueError(f"{shards_dir}/manifest.json: scenes {unknown or names} not found; "
                             f"known: {sorted(manifest.scenes)[:10]}")
    unlabelled = [s for s in names if not manifest.scenes[s].meta.get("labelled", True)]
    if unlabelled:
        raise ValueError(f"{shards_dir}/manifest.json: scenes {unlabelled} have no labels (field 'labelled' is "
                         "false: captures for inference only); training, finetuning and evaluation need labels: "
                         "shard them apart from the training scenes and label them with `sray label`")
    return manifest, names


def make_train_loader(shards_dir: Path, *, n_source: int, top_k: int, rays_per_batch: int, batches_per_epoch: int,
                      rank: int, world_size: int, num_workers: int, seed: int, scenes: list[str] | None = None,
                      cache_scenes: int = 2, visit_samples: int = 16, pin_memory: bool = False,
                      augment: Augmentation | None = None, source_labels: bool = False) -> EpochLoader:
    """The training DataLoader of one rank: one :class:`TrainSample` per step (``batch_size=None``). ``scenes``:
    None = every scene of role ``train`` (name a test scene to finetune on it); ``source_labels``: samples also carry
    their sources' class ids, from the queries' pool (no held-out or test view's labels are read)."""
    manifest, names = _open(shards_dir, scenes)
    if not 0 <= rank < world_size:
        raise ValueError(f"rank {rank} is outside 0..{world_size - 1}")
    if not 1 <= n_source <= top_k <= int(manifest.neighbours["k"]):
        raise ValueError(f"need 1 <= n_source ({n_source}) <= top_k ({top_k}) <= the shards' neighbours per view "
                         f"({manifest.neighbours['k']}); re-shard with a larger --neighbours or lower top_k")
    if rays_per_batch < 1 or batches_per_epoch < 1 or cache_scenes < 1 or num_workers < 0:
        raise ValueError(f"rays_per_batch ({rays_per_batch}), batches_per_epoch ({batches_per_epoch}) and "
                         f"cache_scenes ({cache_scenes}) must be >= 1, num_workers ({num_workers}) >= 0")
    dataset = TrainTuples(Path(shards_dir), manifest, names, n_source=n_source, top_k=top_k,
                          rays_per_batch=rays_per_batch, batches_per_epoch=batches_per_epoch, rank=rank,
                          world_size=world_size, seed=seed, cache_scenes=cache_scenes, visit_samples=visit_samples,
                          augment=augment, source_labels=source_labels)
    for scene, pool in dataset.pools.items():
        if len(pool) < n_source + 1:
            raise ValueError(f"scene {scene!r}: {len(pool)} query/source views, n_source + 1 = {n_source + 1} "
                             "needed; lower n_source or drop the scene")
    return EpochLoader(dataset, batch_size=None, num_workers=num_workers, pin_memory=pin_memory)


def make_eval_samples(shards_dir: Path, scene: str, split: str = "test", source_split: str | None = None,
                      n_source: int = 8, *, manifest: Manifest | None = None) -> Iterator[EvalSample]:
    """Evaluation samples of ``scene``'s ``split`` views in order, each with its top ``n_source`` neighbours in
    ``source_split`` (default ``source`` in test scenes, else ``train``); validated before the generator returns."""
    manifest, _ = _open(shards_dir, [scene], manifest)
    meta = SceneMeta.from_json(manifest.scenes[scene].meta)
    source_split = source_split or ("source" if meta.role == "test" else "train")
    for name in (split, source_split):
        if name not in meta.splits:
            raise ValueError(f"{shards_dir}/manifest.json: scene {scene!r} has no {name!r} split "
                             f"(splits: {sorted(meta.splits)})")
    views = read_scene_views(Path(shards_dir), manifest.scenes[scene])
    allowed = set(meta.splits[source_split])
    plan = [(q, ranked_candidates(views[q], allowed, n_source)) for q in meta.splits[split]]
    for q, sources in plan:
        if len(sources) < n_source:
            raise ValueError(f"scene {scene!r}, view {q!r}: {len(sources)} ranked {source_split!r} neighbours, "
                             f"n_source={n_source} needed; lower n_source or re-shard with a larger --neighbours")
    return (eval_sample(views, q, sources, scene, meta.near, meta.far) for q, sources in plan)
