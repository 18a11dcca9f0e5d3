"""The world a stability preset builds without a checkpoint, kept in ``<out>/world`` for later runs: scenes and shards,
a ``sray train`` job per S-Ray variant (full CRA, ``attention=none``), 2d-transfer's segmenter (``models.json``)."""

from __future__ import annotations

import json
import time
from pathlib import Path

from sray.data_tools.atomic import atomic_write_json
from sray.data_tools.synth.world import make_world
from sray.platform.config.recipes import get_recipe
from sray.platform.eval.segmenter_training import train_segmenter
from sray.platform.stability.axes import Preset
from sray.platform.stability.rows import SuiteModels
from sray.platform.train.launcher import launch_training

CHECKPOINT_ATTENTION = {"checkpoint": "full", "checkpoint_no_cra": "none"}
"""``SuiteModels`` field of each pretrained S-Ray checkpoint -> its ``model.attention``."""
MODELS_FILE = "models.json"


def world_shards(preset: Preset, out: Path) -> Path:
    """The preset's procedural scenes (seed 0), sharded; one already sharded under ``out`` is reused as it is."""
    return make_world(preset.world.scenes, out / "world")


def pretrain(role: str, preset: Preset, shards: Path, out: Path, tracking_uri: str) -> Path:
    """The best (else latest) checkpoint of one ``sray train`` job of the S-Ray checkpoint ``role``."""
    w = preset.world
    cfg = get_recipe("synth-paper" if preset.name == "gpu" else "synth-small")
    cfg.model.attention, cfg.model.n_source = CHECKPOINT_ATTENTION[role], w.train_n_source
    cfg.model.n_coarse, cfg.model.n_fine = w.n_coarse, w.n_fine
    cfg.data.shards, cfg.data.rays_per_batch, cfg.data.top_k = str(shards), w.rays, w.train_n_source + 2
    cfg.optim.steps = w.pretrain_steps
    cfg.run.workers, cfg.run.output_dir, cfg.run.tracking_uri = w.workers, str(out / "world" / "train"), tracking_uri
    cfg.run.experiment, cfg.run.register_model = "sray-stability", ""
    cfg.run.val_every = cfg.run.ckpt_every = max(w.pretrain_steps // 2, 1)
    if preset.name == "toy":
        cfg.data.loader_workers, cfg.data.val_views_per_scene, cfg.run.log_every = 0, 1, 1
    cfg.run.name = f"stability-{CHECKPOINT_ATTENTION[role]}-{time.strftime('%Y%m%d-%H%M%S', time.gmtime())}"
    outcome = launch_training(cfg)
    return Path(outcome.best_checkpoint or outcome.latest_checkpoint)


def pretrain_segmenter(preset: Preset, shards: Path, out: Path) -> Path:
    """The folder of ``2d-transfer``'s segmenter trained for the preset's CPU seconds."""
    w, folder = preset.world, out / "world" / "segmenter"
    train_segmenter(shards, w.segmenter_cpu_seconds, folder, seed=0, n_source=w.train_n_source,
                    top_k=w.train_n_source + 2)
    return folder


def world_models(preset: Preset, shards: Path, out: Path, tracking_uri: str) -> SuiteModels:
    """Every model the preset's rows may need, pretraining the missing ones (each once, recorded)."""
    record_path = out / "world" / MODELS_FILE
    record = json.loads(record_path.read_text()) if record_path.exists() else {}
    for role in (*CHECKPOINT_ATTENTION, "segmenter"):
        if role not in record or not Path(record[role]).exists():
            record[role] = str(pretrain(role, preset, shards, out, tracking_uri) if role in CHECKPOINT_ATTENTION
                               else pretrain_segmenter(preset, shards, out))
            atomic_write_json(record_path, record)
    return SuiteModels(**{role: Path(path) for role, path in record.items()})
