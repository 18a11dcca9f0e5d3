"""Canonical scenes -> webdataset tar shards grouped by scene, plus ``manifest.json`` (members, manifest and safety
rules: docs/data.md, "Shards and loader"): same input, same bytes; a folder with a manifest is complete."""

from __future__ import annotations

import hashlib
import io
import json
import re
import tarfile
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from tqdm import tqdm

from sray.data_tools.atomic import TEMP_NAME, atomic_write_bytes
from sray.data_tools.check.scenes import check_dataset
from sray.data_tools.png import depth_to_png16, encode_png
from sray.data_tools.scene import Scene, View, depth_views, source_pool
from sray.data_tools.scene_folder import list_scenes, read_scene
from sray.data_tools.shards.manifest import MANIFEST_NAME, Manifest, SceneEntry, ShardEntry, manifest_bytes, sha256_file
from sray.data_tools.shards import neighbours as nb

KEY_SEPARATOR = "__"
"""Between scene name and view id in a sample key."""
SHARD_NAME = re.compile(r"^.+-\d{6}\.tar$")


class DatasetRejected(ValueError):
    """The input scenes fail ``sray data check``; ``problems`` lists why (file, what, fix)."""

    def __init__(self, problems: list) -> None:
        self.problems = list(problems)
        lines = "\n".join(f"  {p.file}: {p.what} (fix: {p.fix})" for p in self.problems)
        super().__init__(f"{len(self.problems)} problem(s) found by `sray data check`; nothing was sharded:\n{lines}")


@dataclass
class ShardResult:
    """What :func:`write_shards` did: the manifest on disk, shards (re)written, left alone (same bytes), deleted."""

    manifest: Manifest
    written: list[str] = field(default_factory=list)
    unchanged: list[str] = field(default_factory=list)
    removed: list[str] = field(default_factory=list)


def sample_key(scene: str, view_id: str) -> str:
    """The webdataset key of a view; refuses '.' and '/' (webdataset splits keys on dots)."""
    for what, name in (("scene name", scene), ("view id", view_id)):
        if "." in name or "/" in name or not name:
            raise ValueError(f"scene {scene!r}: {what} {name!r} contains '.' or '/' or is empty; rename it "
                             "in scene.json / cameras.json (webdataset splits sample keys on dots)")
    return f"{scene}{KEY_SEPARATOR}{view_id}"


def json_bytes(obj: object) -> bytes:
    """Compact JSON with sorted keys (deterministic bytes)."""
    return json.dumps(obj, sort_keys=True, separators=(",", ":")).encode()


def tar_bytes(members: list[tuple[str, bytes]]) -> bytes:
    """An uncompressed tar of ``(name, data)`` members with fixed headers (same input -> same bytes)."""
    buf = io.BytesIO()
    with tarfile.open(fileobj=buf, mode="w", format=tarfile.GNU_FORMAT) as tar:
        for name, data in members:
            info = tarfile.TarInfo(name)  # fixed defaults: mtime 0, uid/gid 0, no user names, mode 0644
            info.size = len(data)
            tar.addfile(info, io.BytesIO(data))
    return buf.getvalue()


def view_members(scene: str, view: View, neighbours: nb.Neighbours, scene_json: dict | None
                 ) -> list[tuple[str, bytes]]:
    """Tar members of one view sample (``scene_json`` only on a shard's first sample)."""
    key = sample_key(scene, view.view_id)
    camera = {"K": np.asarray(view.K, np.float64).tolist(), "c2w": np.asarray(view.c2w, np.float64).tolist(),
              "image_size": list(view.hw)}
    members = [(f"{key}.rgb.png", encode_png(view.rgb)),
               (f"{key}.depth.png", encode_png(depth_to_png16(view.depth))),
               (f"{key}.label.png", encode_png(view.label.astype(np.uint16))),
               (f"{key}.camera.json", json_bytes(camera)),
               (f"{key}.neighbours.json", json_bytes(neighbours.to_json()))]
    if scene_json is not None:
        members.append((f"{key}.scene.json", json_bytes(scene_json)))
    return members


def scene_neighbours(scene: Scene, k: int, bar: tqdm | None = None
                     ) -> tuple[dict[str, nb.Neighbours], tuple[int, int]]:
    """Read every view once (cameras + a depth grid) and rank its neighbours; returns them and (H, W). A blind
    view's depth (``neighbours.blind_views``) is never sampled; the fallback depth comes from ``scene.depth_views``."""
    meta = scene.meta
    blind = nb.blind_views(meta)
    Ks, c2ws, samples, hw = [], [], {}, None
    for view in scene.views():
        if hw is not None and view.hw != hw:
            raise ValueError(f"scene {meta.name!r}, view {view.view_id!r}: image size {view.hw} differs from "
                             f"{hw}; resize every view of a scene to one size before sharding")
        hw = view.hw
        Ks.append(np.asarray(view.K, np.float64))
        c2ws.append(np.asarray(view.c2w, np.float64))
        if view.view_id not in blind:
            samples[view.view_id] = nb.grid_samples(view.depth)
        if bar is not None:
            bar.update(1)
    if hw is None:
        raise ValueError(f"scene {meta.name!r}: field 'view_ids' is empty; a scene needs views")
    fallback = nb.fallback_depth([samples[v] for v in depth_views(meta)], (meta.near, meta.far))
    index = {v: i for i, v in enumerate(meta.view_ids)}
    points = {v: nb.grid_points(s, Ks[index[v]], c2ws[index[v]], fallback) for v, s in samples.items()}
    return nb.rank_neighbours(meta.view_ids, np.stack(Ks), np.stack(c2ws), hw, points, source_pool(meta), k), hw


def scene_shards(scene: Scene, ranked: dict[str, nb.Neighbours], views_per_shard: int,
                 bar: tqdm) -> Iterator[tuple[str, int, bytes]]:
    """(file name, view count, tar bytes) of each shard of one scene, in view order."""
    meta = scene.meta
    for index, start in enumerate(range(0, len(meta.view_ids), views_per_shard)):
        ids = meta.view_ids[start:start + views_per_shard]
        members = []
        for j, vid in enumerate(ids):
            members += view_members(meta.name, scene.read_view(vid), ranked[vid], meta.to_json() if j == 0 else None)
            bar.update(1)
        yield f"{meta.name}-{index:06d}.tar", len(ids), tar_bytes(members)


def _label_spaces(scenes: list[Scene]) -> dict[str, list[str]]:
    """Class names per label space; refuses two scenes giving one space different class lists."""
    spaces: dict[str, list[str]] = {}
    for scene in scenes:
        names = spaces.setdefault(scene.meta.label_space, list(scene.meta.class_names))
        if names != list(scene.meta.class_names):
            raise ValueError(f"scene {scene.meta.name!r}: field 'class_names' differs from another scene's list "
                             f"for label space {scene.meta.label_space!r}; give the two spaces different names")
    return dict(sorted(spaces.items()))


def is_current(path: Path, data: bytes) -> bool:
    """True when ``path`` already holds exactly ``data`` (size, then sha256)."""
    return path.is_file() and path.stat().st_size == len(data) and sha256_file(path) == hashlib.sha256(data).hexdigest()


def write_shards(scenes_dir: Path, out_dir: Path, *, views_per_shard: int = 256, neighbours: int = 32,
                 progress: bool = True) -> ShardResult:
    """Shard every scene of ``scenes_dir`` (sray layout) into ``out_dir`` with ``neighbours`` ranked source views per
    view, then write the manifest; :class:`DatasetRejected` when ``sray data check`` rejects the input."""
    if views_per_shard < 1 or neighbours < 1:
        raise ValueError(f"views_per_shard ({views_per_shard}) and neighbours ({neighbours}) must be >= 1")
    problems = check_dataset(Path(scenes_dir))
    if problems:
        raise DatasetRejected(problems)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    for stale in out.iterdir():
        if TEMP_NAME.match(stale.name):
            stale.unlink()
    scenes = [read_scene(p) for p in list_scenes(Path(scenes_dir))]
    label_spaces = _label_spaces(scenes)
    written, unchanged, entries, scene_entries = [], [], [], {}
    with tqdm(total=2 * sum(len(s.meta.view_ids) for s in scenes), unit="view", disable=not progress) as bar:
        for scene in scenes:
            bar.set_description(f"{scene.meta.name}: neighbours")
            ranked, hw = scene_neighbours(scene, neighbours, bar)
            bar.set_description(f"{scene.meta.name}: shards")
            names = []
            for name, n_views, data in scene_shards(scene, ranked, views_per_shard, bar):
                if is_current(out / name, data):
                    unchanged.append(name)
                else:
                    if not written:  # the folder stops looking complete before its first shard changes
                        (out / MANIFEST_NAME).unlink(missing_ok=True)
                    atomic_write_bytes(out / name, data)
                    written.append(name)
                entries.append(ShardEntry(path=name, scene=scene.meta.name, n_views=n_views,
                                          sha256=hashlib.sha256(data).hexdigest(), bytes=len(data)))
                names.append(name)
            scene_entries[scene.meta.name] = SceneEntry(meta=scene.meta.to_json(), shards=names,
                                                        n_views=len(scene.meta.view_ids), image_size=list(hw))
    manifest = Manifest(
        shards=sorted(entries, key=lambda e: e.path), scenes=dict(sorted(scene_entries.items())),
        label_spaces=label_spaces,
        neighbours={"rule": nb.RULE, "version": nb.RULE_VERSION, "k": neighbours, "grid": list(nb.GRID),
                    "min_points": nb.MIN_POINTS, "pool": "train scenes: train split minus test split; "
                    "test scenes: source plus finetune splits",
                    "test_views": "test split of test scenes: score = fraction of each candidate's own depth-grid "
                    "points in front of and inside the query camera (the query's depth and labels are never read)",
                    "fallback_depth": "median grid depth of train scenes' views, of test scenes' source pool"},
        extra={"views_per_shard": views_per_shard})
    if not is_current(out / MANIFEST_NAME, manifest_bytes(manifest)):
        atomic_write_bytes(out / MANIFEST_NAME, manifest_bytes(manifest))
    listed = {e.path for e in entries}
    removed = [p.name for p in sorted(out.iterdir()) if SHARD_NAME.match(p.name) and p.name not in listed]
    for name in removed:
        (out / name).unlink()
    return ShardResult(manifest=manifest, written=written, unchanged=unchanged, removed=removed)
