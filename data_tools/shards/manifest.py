"""``manifest.json``: the index of a shard folder, and the check that its shards are intact.

The manifest is written last and atomically by ``sray data shard``: a folder with a manifest is
complete; its shards match the listed sizes and sha256 checksums unless something changed them
afterwards, which :func:`verify_shards` reports.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import asdict, dataclass, field
from pathlib import Path

FORMAT = "sray-shards"
VERSION = 1
MANIFEST_NAME = "manifest.json"


@dataclass
class ShardEntry:
    """One tar shard (all its views belong to one scene)."""

    path: str
    """File name relative to the shard folder, ``<scene>-NNNNNN.tar``."""
    scene: str
    """Scene whose views the shard holds."""
    n_views: int
    """Views (samples) in the shard."""
    sha256: str
    """Hex sha256 of the whole file."""
    bytes: int
    """File size in bytes."""


@dataclass
class SceneEntry:
    """One scene: its metadata and where its views are."""

    meta: dict
    """``SceneMeta.to_json()``: label space, class names, view ids, splits, near/far, role."""
    shards: list[str]
    """Shard file names holding the scene's views, in view order."""
    n_views: int
    """Views stored for the scene (all of ``meta['view_ids']``)."""
    image_size: list[int]
    """[H, W] shared by every view of the scene."""


@dataclass
class Manifest:
    """Everything a loader needs to know before opening a shard."""

    shards: list[ShardEntry]
    """Every shard, sorted by file name."""
    scenes: dict[str, SceneEntry]
    """Scenes by name."""
    label_spaces: dict[str, list[str]]
    """Class names of every label space used by the scenes."""
    neighbours: dict
    """The neighbour rule and its parameters (rule, version, k, grid, pool rule)."""
    format: str = FORMAT
    """Always ``sray-shards``."""
    version: int = VERSION
    """Format version; readers refuse versions they do not know."""
    extra: dict = field(default_factory=dict)
    """Free-form provenance (shard writer options)."""

    def to_json(self) -> dict:
        """JSON form (key order fixed, so equal manifests serialise to equal bytes)."""
        return asdict(self)

    @classmethod
    def from_json(cls, d: dict, where: str = MANIFEST_NAME) -> Manifest:
        """Parse a manifest; errors name the file and the field."""
        try:
            if d["format"] != FORMAT or d["version"] != VERSION:
                raise ValueError(f"{where}: format {d['format']!r} version {d['version']!r} is not "
                                 f"{FORMAT!r} version {VERSION}; re-run `sray data shard` with this sray")
            return cls(shards=[ShardEntry(**s) for s in d["shards"]],
                       scenes={k: SceneEntry(**v) for k, v in d["scenes"].items()},
                       label_spaces={k: list(v) for k, v in d["label_spaces"].items()},
                       neighbours=dict(d["neighbours"]), extra=dict(d.get("extra", {})))
        except KeyError as e:
            raise ValueError(f"{where}: field {e.args[0]!r} is missing; re-run `sray data shard`") from None
        except TypeError as e:
            raise ValueError(f"{where}: malformed entry ({e}); re-run `sray data shard`") from None


def manifest_bytes(manifest: Manifest) -> bytes:
    """The exact bytes written to ``manifest.json``."""
    return (json.dumps(manifest.to_json(), indent=1, sort_keys=True) + "\n").encode()


def read_manifest(shards_dir: Path) -> Manifest:
    """Read ``shards_dir/manifest.json``; a missing one means the folder is incomplete."""
    path = Path(shards_dir) / MANIFEST_NAME
    try:
        text = path.read_text()
    except FileNotFoundError:
        raise FileNotFoundError(f"{path}: missing; the shard folder is incomplete or was never written: "
                                f"run `sray data shard SCENES_DIR --out {shards_dir}`") from None
    try:
        data = json.loads(text)
    except json.JSONDecodeError as e:
        raise ValueError(f"{path}: not valid JSON ({e}); re-run `sray data shard`") from None
    return Manifest.from_json(data, str(path))


def sha256_file(path: Path, chunk: int = 1 << 20) -> str:
    """Hex sha256 of a file, read in chunks."""
    h = hashlib.sha256()
    with open(path, "rb") as f:
        while block := f.read(chunk):
            h.update(block)
    return h.hexdigest()


def verify_shards(shards_dir: Path, checksums: bool = True) -> list[str]:
    """Problems with a shard folder, one line each (empty when intact).

    Checks the manifest parses, every listed shard exists with the listed size and, when
    ``checksums`` is true, the listed sha256 (a size check alone catches truncation cheaply).
    """
    root = Path(shards_dir)
    try:
        manifest = read_manifest(root)
    except (FileNotFoundError, ValueError) as e:
        return [str(e)]
    fix = f"re-run `sray data shard SCENES_DIR --out {root}`"
    problems = []
    for entry in manifest.shards:
        path = root / entry.path
        if not path.is_file():
            problems.append(f"{path}: missing (listed in {MANIFEST_NAME}); {fix}")
            continue
        size = path.stat().st_size
        if size != entry.bytes:
            problems.append(f"{path}: {size} bytes, manifest says {entry.bytes} (truncated or replaced); {fix}")
        elif checksums and (digest := sha256_file(path)) != entry.sha256:
            problems.append(f"{path}: sha256 {digest[:12]}… differs from the manifest's {entry.sha256[:12]}…; {fix}")
    return problems


def unseen_scenes(shards: Path) -> list[str]:
    """Names of the unseen test scenes (role ``test``) of a shard folder, sorted."""
    return sorted(name for name, e in read_manifest(Path(shards)).scenes.items() if e.meta.get("role") == "test")
