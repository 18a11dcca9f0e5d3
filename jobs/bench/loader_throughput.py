"""``sray bench loader``: training-loader throughput with 0, 1 and 2 DataLoader workers, and bytes per view."""

from __future__ import annotations

import tarfile
import tempfile
import time
from collections import Counter
from pathlib import Path

from sray.data_tools.loader.shard_loader import make_train_loader
from sray.data_tools.scene import SceneMeta, source_pool
from sray.data_tools.shards.manifest import read_manifest
from sray.data_tools.synth.world import World, make_world
from sray.platform.common.bench_doc import Bench

LOADER = Bench("loader", "Shard loader")
BENCH_SCENES, BENCH_VIEWS, BENCH_HW = 2, 20, (240, 320)
"""Procedural data when no shard folder is given: 2 train scenes x 20 views at 320x240 (ScanNet size)."""


def procedural_shards(root: Path, seed: int = 0) -> Path:
    """Generate small procedural scenes under ``root`` and shard them; returns the shard folder."""
    world = World(train_scenes=BENCH_SCENES, test_scenes=0, views=BENCH_VIEWS, height=BENCH_HW[0],
                  width=BENCH_HW[1], seed=seed)
    return make_world(world, root)


def component_bytes(shards_dir: Path) -> tuple[int, Counter]:
    """Views stored and bytes per member kind (``rgb.png``, ..., ``tar overhead``) over all shards."""
    manifest = read_manifest(shards_dir)
    sizes: Counter = Counter()
    for entry in manifest.shards:
        with tarfile.open(Path(shards_dir) / entry.path) as tar:
            members = tar.getmembers()
        for member in members:
            sizes[member.name.split(".", 1)[1]] += member.size
        sizes["tar overhead"] += entry.bytes - sum(m.size for m in members)
    return sum(e.n_views for e in manifest.shards), sizes


def time_loader(shards_dir: Path, workers: int, batches: int, *, rays: int, n_source: int, top_k: int) -> dict:
    """First-batch latency and steady-state samples/s and rays/s of one rank's training loader."""
    loader = make_train_loader(shards_dir, n_source=n_source, top_k=top_k, rays_per_batch=rays,
                               batches_per_epoch=batches + 1, rank=0, world_size=1, num_workers=workers, seed=0)
    start = time.perf_counter()
    stream = iter(loader)
    first = next(stream)
    ready = time.perf_counter()
    count = sum(1 for _ in stream)
    elapsed = time.perf_counter() - ready
    return {"workers": workers, "first_s": ready - start, "samples_s": count / elapsed,
            "rays_s": count * rays / elapsed, "src_shape": tuple(first.sources.rgb.shape)}


def run_loader_benchmark(data: Path | None, batches: int, *, rays: int = 1024, n_source: int = 8,
                         top_k: int = 12) -> tuple[str, str, str]:
    """Time the loader with 0, 1, 2 workers on ``data`` (None: fresh procedural shards); (title, table, notes)."""
    if batches < 1:
        raise ValueError(f"batches must be >= 1, got {batches}")
    with tempfile.TemporaryDirectory(prefix="sray-bench-loader-") as tmp:
        shards = Path(data) if data is not None else procedural_shards(Path(tmp))
        manifest = read_manifest(shards)
        smallest_pool = min(len(source_pool(SceneMeta.from_json(e.meta))) for e in manifest.scenes.values()
                            if e.meta.get("role", "train") == "train")
        top_k = min(top_k, int(manifest.neighbours["k"]), smallest_pool - 1)
        n_source = min(n_source, top_k)
        rows = [time_loader(shards, w, batches, rays=rays, n_source=n_source, top_k=top_k) for w in (0, 1, 2)]
        n_views, sizes = component_bytes(shards)
    total = sum(sizes.values())
    table = "\n".join(
        ["| DataLoader workers | first batch (ms) | samples/s | rays/s |", "|---:|---:|---:|---:|"]
        + [f"| {r['workers']} | {r['first_s'] * 1000:.1f} | {r['samples_s']:.1f} | {r['rays_s']:,.0f} |" for r in rows])
    breakdown = " · ".join(f"{kind} {b / n_views / 1024:.1f}" for kind, b in sizes.most_common())
    m, _, h, w = rows[0]["src_shape"]
    hw = manifest.scenes[next(iter(manifest.scenes))].image_size
    source = f"`{data}`" if data is not None else (f"procedural ({BENCH_SCENES} train scenes x {BENCH_VIEWS} views, "
                                                   "generated and sharded for this run)")
    notes = (f"Data: {source}; {n_views} views at {hw[1]}x{hw[0]}. One sample = 1 query + {m} source views "
             f"({m}x3x{h}x{w} float32) + {rays} rays; top_k={top_k}; {batches} batches timed after the first. "
             f"Each worker caches the encoded views of at most 2 scenes and decodes per sample.\n\n"
             f"On disk: **{total / n_views / 1024:.1f} KiB per view** ({total / 1e6:.2f} MB in {len(manifest.shards)} "
             f"shards); per component (KiB/view): {breakdown}.")
    return "Shard loader throughput", table, notes
