"""``manifest.json``: the index of a shard folder (written last: a folder with a manifest is complete), and
:func:`verify_shards`, which reports shards changed since (size and sha256)."""

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
    """One tar shard of one scene: file name (``<scene>-NNNNNN.tar``), scene, view count, hex sha256, size in bytes."""

    path: str
    scene: str
    n_views: int
    sha256: str
    bytes: int


@dataclass
class SceneEntry:
    """One scene: its ``SceneMeta.to_json()``, its shards in view order, its view count, the [H, W] all views share."""

    meta: dict
    shards: list[str]
    n_views: int
    image_size: list[int]


@dataclass
class Manifest:
    """What a loader needs before opening a shard: every shard (by file name), the scenes by name, each label space's
    class names, the neighbour rule, the format and version (others refused), the writer's options."""

    shards: list[ShardEntry]
    scenes: dict[str, SceneEntry]
    label_spaces: dict[str, list[str]]
    neighbours: dict
    format: str = FORMAT
    version: int = VERSION
    extra: dict = field(default_factory=dict)

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
    """The exact bytes written to ``manifest.json`` (equal manifests give equal bytes)."""
    return (json.dumps(asdict(manifest), indent=1, sort_keys=True) + "\n").encode()


def read_manifest(shards_dir: Path) -> Manifest:
    """Read ``shards_dir/manifest.json``; a missing one means the folder is incomplete."""
    path = Path(shards_dir) / MANIFEST_NAME
    try:
        data = json.loads(path.read_text())
    except FileNotFoundError:
        raise FileNotFoundError(f"{path}: missing; the shard folder is incomplete or was never written: "
                                f"run `sray data shard SCENES_DIR --out {shards_dir}`") from None
    except json.JSONDecodeError as e:
        raise ValueError(f"{path}: not valid JSON ({e}); re-run `sray data shard`") from None
    return Manifest.from_json(data, str(path))


def sha256_file(path: Path) -> str:
    """Hex sha256 of a file, read in chunks."""
    with open(path, "rb") as f:
        return hashlib.file_digest(f, "sha256").hexdigest()


def verify_shards(shards_dir: Path, checksums: bool = True) -> list[str]:
    """Problems with a shard folder, one line each (empty when intact): the manifest parses, every listed shard
    exists with its size and, with ``checksums``, its sha256 (a size check alone catches truncation cheaply)."""
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
