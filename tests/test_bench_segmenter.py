"""``sray bench segmenter``: training with a recipe's settings and overrides, resuming, reading only train
scenes' source pools, and taking S-Ray's own encoder and source-view head from a checkpoint."""

from __future__ import annotations

import dataclasses
from dataclasses import replace
from pathlib import Path

import pytest
import torch
from ceilings_fixtures import shards  # noqa: F401
from fleet_fixtures import one_thread  # noqa: F401
from label_reads import record_label_reads
from train_fixtures import tiny_config

from sray.data_tools.loader.augment import Augmentation
from sray.data_tools.scene import SceneMeta, source_pool
from sray.data_tools.shards.manifest import read_manifest
from sray.jobs.cli import main
from sray.lab.probes.linear_probe import fit_probe, random_encoder
from sray.platform.checkpoints.model_loading import model_from_checkpoint
from sray.platform.config.recipes import get_recipe
from sray.platform.eval import segmenter_training
from sray.platform.eval.segmenter import load_segmenter
from sray.platform.eval.segmenter_training import STATE_FILE, train_segmenter
from sray.platform.train.state import write_initial_checkpoint


def test_cli_trains_a_segmenter_and_loads_it(shards: Path, tmp_path: Path, one_thread: None) -> None:  # noqa: F811
    """``sray bench segmenter`` saves a folder that loads back with its budget, its encoder width and the
    augmentation a ``--set`` gave it recorded; a ``--set`` of a field that does not exist is refused with exit code
    2 before anything is written."""
    assert main(["bench", "segmenter", "--data", str(shards), "--cpu-seconds", "0.2", "--out", str(tmp_path / "seg"),
                 "--recipe", "synth-small", "--encoder-width", "8", "--set", "data.aug.colour_ev=0.2",
                 "--set", "data.aug.noise_sigma=1.5"]) == 0
    model, record = load_segmenter(tmp_path / "seg")
    assert model.cfg.encoder_width == 8 == model.encoder.stem[0].out_channels == record.training["encoder_width"]
    aug = record.training["augmentation"]
    assert aug == dataclasses.asdict(replace(get_recipe("synth-small").data.aug, colour_ev=0.2, noise_sigma=1.5))
    assert main(["bench", "segmenter", "--data", str(shards), "--cpu-seconds", "0.2", "--out", str(tmp_path / "bad"),
                 "--set", "data.aug.colour=0"]) == 2
    assert not (tmp_path / "bad").exists()
    t = record.training
    assert t["steps"] >= 1 and t["cpu_seconds_budget"] == 0.2
    assert t["cpu_seconds"] >= 0.2, "training stopped before its CPU budget"
    assert t["images"] >= t["steps"], "every step trains on at least one labelled source image"
    labels = model.predict(torch.rand(1, 3, 32, 40))
    n_classes = len(next(iter(read_manifest(shards).scenes.values())).meta["class_names"])
    assert labels.shape == (1, 32, 40) and int(labels.min()) >= 0 and int(labels.max()) < n_classes


def test_a_checkpoints_encoder_and_source_head_are_written_as_a_segmenter(shards: Path, tmp_path: Path,
                                                                          one_thread: None) -> None:  # noqa: F811
    """``sray bench segmenter --from-checkpoint`` writes the checkpoint's encoder and source-view head: the loaded
    segmenter's logits equal the S-Ray network's own source-view read-out; a checkpoint without a source-view head,
    or the flag mixed with a training budget, is refused with exit code 2 and nothing written."""
    cfg = tiny_config(shards, tmp_path)
    cfg.model.lambda_src_sem = 1.0
    checkpoint = write_initial_checkpoint(cfg, tmp_path / "job" / "checkpoints" / "step_000000000")
    assert main(["bench", "segmenter", "--from-checkpoint", str(checkpoint), "--out", str(tmp_path / "seg")]) == 0
    seg, record = load_segmenter(tmp_path / "seg")
    net, _ = model_from_checkpoint(checkpoint)
    rgb = torch.rand(2, 3, 32, 40, generator=torch.Generator().manual_seed(0))
    with torch.no_grad():
        torch.testing.assert_close(seg(rgb), net.src_head(net.encoder(rgb), (32, 40)), rtol=0, atol=0)
    assert record.training["steps"] == 0 and "checkpoint step 0" in record.budget()
    bare = write_initial_checkpoint(tiny_config(shards, tmp_path / "bare"), tmp_path / "bare" / "step_000000000")
    assert main(["bench", "segmenter", "--from-checkpoint", str(bare), "--out", str(tmp_path / "no-head")]) == 2
    assert main(["bench", "segmenter", "--from-checkpoint", str(checkpoint), "--data", str(shards),
                 "--out", str(tmp_path / "mixed")]) == 2
    assert main(["bench", "segmenter", "--out", str(tmp_path / "nothing")]) == 2
    assert not any((tmp_path / name).exists() for name in ("no-head", "mixed", "nothing"))


def test_an_interrupted_segmenter_training_resumes_to_the_same_weights(shards: Path, tmp_path: Path,
                                                                      monkeypatch: pytest.MonkeyPatch,
                                                                      one_thread: None) -> None:  # noqa: F811
    """Killed right after its state at step 6 (epochs of 3 steps) and started again, a training ends at step 7 with
    exactly the weights of an uninterrupted one, its CPU seconds summed over both runs; a state from other
    settings is refused by name."""
    monkeypatch.setattr(segmenter_training, "EPOCH_STEPS", 3)
    kwargs = {"augment": Augmentation(min_source=2, colour_ev=0.3), "n_source": 3, "top_k": 8, "max_steps": 7,
              "progress": False}
    whole = train_segmenter(shards, 1e6, tmp_path / "whole", **kwargs)
    write = segmenter_training._write_state

    def write_then_die(out: Path, state: dict) -> None:
        write(out, state)
        if state["steps"] == 6:
            raise KeyboardInterrupt("killed")

    monkeypatch.setattr(segmenter_training, "_write_state", write_then_die)
    with pytest.raises(KeyboardInterrupt):
        train_segmenter(shards, 1e6, tmp_path / "cut", **kwargs)
    monkeypatch.setattr(segmenter_training, "_write_state", write)
    first_run = torch.load(tmp_path / "cut" / STATE_FILE, weights_only=True)["cpu_seconds"]
    with pytest.raises(ValueError, match=f"{STATE_FILE}: an unfinished segmenter training with other settings \\(seed"):
        train_segmenter(shards, 1e6, tmp_path / "cut", seed=1, **kwargs)
    resumed = train_segmenter(shards, 1e6, tmp_path / "cut", **kwargs)
    assert (resumed.training["steps"], whole.training["steps"]) == (7, 7)
    assert resumed.training["images"] == whole.training["images"] and resumed.training["cpu_seconds"] > first_run
    assert not (tmp_path / "cut" / STATE_FILE).exists()
    cut, _ = load_segmenter(tmp_path / "cut")
    reference, _ = load_segmenter(tmp_path / "whole")
    for (name, a), b in zip(reference.state_dict().items(), cut.state_dict().values(), strict=True):
        torch.testing.assert_close(b, a, rtol=0, atol=0, msg=name)


def test_segmenter_and_probe_read_only_train_scene_source_pools(shards: Path, tmp_path: Path,
                                                                monkeypatch: pytest.MonkeyPatch,
                                                                one_thread: None) -> None:  # noqa: F811
    """Every label map the segmenter's training and the probe's fit decode belongs to a train scene's source
    pool: never a test scene's view, never a held-out view of a train scene."""
    read = record_label_reads(monkeypatch)
    train_segmenter(shards, 0.3, tmp_path / "seg", augment=Augmentation(min_source=2), n_source=3, top_k=8,
                    progress=False)
    fit_probe(random_encoder(32, 0), shards, tiny_config(shards, tmp_path).model, steps=2, max_views=100)
    manifest = read_manifest(shards)
    allowed = {(name, v) for name, entry in manifest.scenes.items() if entry.meta.get("role") == "train"
               for v in source_pool(SceneMeta.from_json(entry.meta))}
    seen = set(read)
    assert seen and seen <= allowed
    assert len(seen) == len(allowed)  # the probe's fit read every pool view (max_views above the pool size)
