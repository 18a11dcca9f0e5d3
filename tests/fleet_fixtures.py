"""A tiny shared S-Ray checkpoint (written without Ray Train), a tiny 2D segmenter and a tiny fleet config for
the fleet tests.

Use from a test module (the tests folder is not a package)::

    from fleet_fixtures import one_thread, tiny_checkpoint, tiny_fleet_config, tiny_segmenter  # noqa: F401
    from train_fixtures import tiny_shards  # noqa: F401
"""

from __future__ import annotations

from pathlib import Path

import pytest
import torch
from train_fixtures import tiny_config

from sray.platform.config.fleet_config import FleetConfig
from sray.platform.eval.segmenter_training import train_segmenter
from sray.platform.train.state import write_initial_checkpoint


def write_tiny_checkpoint(shards: Path, folder: Path, seed: int = 0, attention: str = "full") -> Path:
    """A step-0 checkpoint of a seeded tiny ``RayBatchLoss`` (the tiny training config's network, with the
    ``attention`` variant)."""
    cfg = tiny_config(shards, folder)
    cfg.model.attention, cfg.run.seed = attention, seed
    return write_initial_checkpoint(cfg, folder / "checkpoints" / "step_000000000")


@pytest.fixture(scope="session")
def tiny_checkpoint(tiny_shards: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Folder of the tiny shared checkpoint (built once per session, at a fixed path)."""
    folder = tmp_path_factory.getbasetemp() / "fleet-checkpoint"
    path = folder / "checkpoints" / "step_000000000"
    if not (path / "state.pt").exists():
        write_tiny_checkpoint(tiny_shards, folder)
    return path


@pytest.fixture(scope="session")
def tiny_segmenter(tiny_shards: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Folder of a 2D segmenter trained for half a CPU second on the tiny shards' train scenes (built once per
    session, at a fixed path; ``sray bench segmenter``'s output)."""
    folder = tmp_path_factory.getbasetemp() / "fleet-segmenter"
    if not (folder / "segmenter.json").exists():
        train_segmenter(tiny_shards, 0.5, folder, seed=0, n_source=2, top_k=4, progress=False)
    return folder


@pytest.fixture(scope="module")
def one_thread():
    """Torch on one thread for the module (restored after): tiny models run fastest that way on a busy
    2-core machine, as fleet tasks with one reserved CPU do."""
    previous = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(previous)


def tiny_fleet_config(**finetune: object) -> FleetConfig:
    """Seconds per scene: 3 held-out sources, stride-4 renders, tiny Semantic-NeRF, quick retries."""
    cfg = FleetConfig(max_parallel=2, cpus_per_task=1.0, retries=1, retry_backoff_s=0.1)
    ft = cfg.finetune
    ft.max_steps, ft.eval_every, ft.patience, ft.lr, ft.held_out.n_source, ft.held_out.stride = 6, 3, 2, 1e-2, 3, 4
    cfg.nerf.depth, cfg.nerf.width, cfg.nerf.skip_layer, cfg.nerf.pos_freqs, cfg.nerf.dir_freqs = 2, 32, 1, 4, 2
    for key, value in finetune.items():
        setattr(ft, key, value)
    return cfg


def kept_point(curve: list[dict], min_delta: float) -> dict:
    """The evaluation a finetune keeps as its best, replayed over its ``curve`` by a plain loop: the first point,
    then each later one that beats the kept score by more than ``min_delta`` (``finetune.min_delta``)."""
    kept = curve[0]
    for point in curve[1:]:
        if point["miou"] > kept["miou"] + min_delta:
            kept = point
    return kept
