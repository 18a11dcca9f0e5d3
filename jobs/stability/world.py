"""The world a stability preset builds when it is given no data and no checkpoints: procedural scenes,
their shards, and one pretraining per S-Ray variant (full CRA, and ``attention=none``), each a real
``sray train`` job (Ray Train, tracked).

Every piece is kept under ``<out>/world`` and reused by a later run: scenes already generated are
skipped, shards are written once, and a finished pretraining is recorded in ``checkpoints.json``.
"""

from __future__ import annotations

import json
import time
from pathlib import Path

from sray.data_tools.atomic import atomic_write_json
from sray.data_tools.synth.world import make_world
from sray.platform.config.recipes import get_recipe
from sray.platform.stability.presets import Preset
from sray.platform.train.launcher import launch_training

VARIANT_ATTENTION = {"sray": "full", "sray-no-cra": "none"}
"""S-Ray method of the suite -> the ``model.attention`` it is pretrained with."""
CHECKPOINTS_FILE = "checkpoints.json"
"""Method -> pretrained checkpoint folder, under ``<out>/world``."""


def world_shards(preset: Preset, out: Path) -> Path:
    """Generate the preset's procedural scenes (seed 0) and shard them; a world already sharded under ``out`` is
    reused as it is (its checkpoints were pretrained on it), even if the generator has changed since."""
    return make_world(preset.world.scenes, out / "world")


def pretrain(method: str, preset: Preset, shards: Path, out: Path, tracking_uri: str) -> Path:
    """One ``sray train`` job of the method's variant on the train scenes; its best (else latest) checkpoint."""
    w = preset.world
    cfg = get_recipe("synth-paper" if preset.name == "gpu" else "synth-small")
    cfg.model.attention, cfg.model.n_source = VARIANT_ATTENTION[method], w.train_n_source
    cfg.model.n_coarse, cfg.model.n_fine = w.n_coarse, w.n_fine
    cfg.data.shards, cfg.data.rays_per_batch, cfg.data.top_k = str(shards), w.rays, w.train_n_source + 2
    cfg.optim.steps = w.pretrain_steps
    cfg.run.workers, cfg.run.output_dir, cfg.run.tracking_uri = w.workers, str(out / "world" / "train"), tracking_uri
    cfg.run.experiment, cfg.run.register_model = "sray-stability", ""
    cfg.run.val_every = cfg.run.ckpt_every = max(w.pretrain_steps // 2, 1)
    if preset.name == "toy":
        cfg.data.loader_workers, cfg.data.val_views_per_scene, cfg.run.log_every = 0, 1, 1
    cfg.run.name = f"stability-{method}-{time.strftime('%Y%m%d-%H%M%S', time.gmtime())}"
    outcome = launch_training(cfg)
    return Path(outcome.best_checkpoint or outcome.latest_checkpoint)


def world_checkpoints(preset: Preset, shards: Path, out: Path, tracking_uri: str,
                      methods: list[str]) -> dict[str, Path]:
    """The pretrained checkpoint of every S-Ray method in ``methods``, pretraining the missing ones."""
    record_path = out / "world" / CHECKPOINTS_FILE
    record = json.loads(record_path.read_text()) if record_path.exists() else {}
    for method in (m for m in VARIANT_ATTENTION if m in methods):
        if method not in record or not Path(record[method]).exists():
            record[method] = str(pretrain(method, preset, shards, out, tracking_uri))
            atomic_write_json(record_path, record)
    return {m: Path(p) for m, p in record.items() if m in methods}
