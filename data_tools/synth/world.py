"""One procedural world: its settings (:class:`World`) and :func:`make_world`, which generates, shards and verifies it
in a folder (``scenes/``, ``shards/``, the manifest last, recording the :class:`World`). Without a manifest it is
(re)generated, skipping finished parts; one recording this world is reused even after generator changes (trained models
stay comparable), another's refused."""

from __future__ import annotations

from dataclasses import asdict, dataclass, replace
from pathlib import Path

from sray.data_tools.shards.manifest import MANIFEST_NAME, Manifest, read_manifest, verify_shards
from sray.data_tools.shards.writer import write_shards
from sray.data_tools.synth import domains
from sray.data_tools.synth.dataset import generate_dataset, scene_name, scene_seed

SCENES, SHARDS = "scenes", "shards"  # sub-folders of a world folder


@dataclass(frozen=True)
class World:
    """The settings that determine a procedural world: same settings, same files."""

    train_scenes: int
    test_scenes: int
    views: int
    """Views per scene (a test scene needs at least 20: 8 source, 8 finetune, 4 test)."""
    height: int
    width: int
    seed: int = 0
    """Dataset seed; each scene's own seed is derived from it."""
    neighbours: int = 32
    """Ranked source views kept per view in the shards (a loader's ``top_k`` must not exceed it)."""
    split: str = "in-distribution"
    """Region the test scenes are drawn from, one of ``domains.SPLITS``; training scenes are always in-distribution."""
    randomise: float = 0.0
    """Strength (0-1) of the training scenes' appearance randomisation (``domains``), 0 = off; never in test scenes."""

    def __post_init__(self) -> None:
        """ValueError naming the valid splits or the randomisation's range."""
        domains.domain_of(self.split)
        domains.domain_of("in-distribution", self.randomise)


SPLIT_RESULTS = {"zero_shot": "in-distribution", "validation": "validation",
                 "zero_shot_appearance": "appearance-shift", "zero_shot_geometry": "geometry-shift"}
"""Result names of the evaluation splits (docs/studies: ``metrics`` keys) and the split each world is drawn from."""


def evaluation_worlds(world: World, rooms: int = 16) -> dict[str, World]:
    """A training world's evaluation worlds by result name (:data:`SPLIT_RESULTS`), ``rooms`` test rooms each."""
    return {name: replace(world, train_scenes=0, test_scenes=rooms, split=split)
            for name, split in SPLIT_RESULTS.items()}


class WorldFolderError(ValueError):
    """A world folder that cannot be used: it holds another world, or its shards no longer match the manifest."""


def recorded_differences(world: World, manifest: Manifest) -> list[str]:
    """Each field in which the world ``manifest`` records differs from ``world``, as ``"views 40 (asked 20)"``;
    empty when it records ``world``. The seed is compared scene by scene when the scene counts agree."""
    scenes = manifest.scenes.values()
    roles = [s.meta.get("role") for s in scenes]
    recorded = {"train_scenes": roles.count("train"), "test_scenes": roles.count("test"),
                "views": _one({s.n_views for s in scenes}), "height": _one({s.image_size[0] for s in scenes}),
                "width": _one({s.image_size[1] for s in scenes}), "neighbours": manifest.neighbours.get("k"),
                "split": _one({s.meta.get("extra", {}).get("split", "in-distribution") for s in scenes
                               if s.meta.get("role") == "test"} or {"in-distribution"}),
                "randomise": _one({float(s.meta.get("extra", {}).get("randomise", 0.0)) for s in scenes
                                   if s.meta.get("role") == "train"} or {world.randomise})}
    asked = asdict(world)
    problems = [f"{name} {value} (asked {asked[name]})" for name, value in recorded.items() if value != asked[name]]
    if recorded["train_scenes"] == world.train_scenes and recorded["test_scenes"] == world.test_scenes:
        for role, count in (("train", world.train_scenes), ("test", world.test_scenes)):
            for i in range(count):
                entry = manifest.scenes.get(scene_name(role, i))
                split = world.split if role == "test" else "in-distribution"
                if entry is None or entry.meta.get("extra", {}).get("seed") != scene_seed(world.seed, role, i, split):
                    return [*problems, f"seed: scene {scene_name(role, i)} was not generated from seed {world.seed}"]
    return problems


def _one(values: set[int]) -> int | list[int]:
    """The value all scenes share, else every value found (sorted)."""
    return next(iter(values)) if len(values) == 1 else sorted(values)


def make_world(world: World, root: Path, progress: bool = True, workers: int = 1) -> Path:
    """The verified shard folder of ``world`` under ``root``, generated, checked and sharded unless ``root`` holds it
    (``workers`` scenes rendered at once); :class:`WorldFolderError` when ``root`` holds another world or damaged
    shards, :class:`~sray.data_tools.shards.writer.DatasetRejected` when ``sray data check`` fails."""
    root = Path(root)
    shards = root / SHARDS
    if (shards / MANIFEST_NAME).exists():
        problems = recorded_differences(world, read_manifest(shards))
        if problems:
            raise WorldFolderError(f"{shards / MANIFEST_NAME}: this folder holds another procedural world than the "
                                   f"one asked: {'; '.join(problems)}. Delete {root} to generate the asked world "
                                   "there, or choose another output folder")
    else:
        generate_dataset(root / SCENES, n_train=world.train_scenes, n_test=world.test_scenes, n_views=world.views,
                         height=world.height, width=world.width, seed=world.seed, progress=progress,
                         workers=workers, split=world.split, randomise=world.randomise)
        write_shards(root / SCENES, shards, neighbours=world.neighbours, progress=progress)
    damaged = verify_shards(shards)
    if damaged:
        raise WorldFolderError(f"{shards}: {len(damaged)} shard problem(s):\n" + "\n".join(damaged)
                               + f"\n(or delete {root} to generate the world again)")
    return shards
