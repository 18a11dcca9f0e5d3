"""``sray migrate`` on real training jobs written by sray at commits 7734061 and 7966ddf (``tests/fixtures/sray_*``,
each built by its ``make_fixture.py`` from that commit's code; the second with a Semantic-NeRF scene artifact): today's
load paths refuse them in one line naming the command; migrated, they load and render exactly what they rendered
there. Older layouts that 7734061 still read (flat augmentation keys, runtime settings in the model section,
``net.``-prefixed weights, fault settings in the run section), sweep records and segmenter folders migrate too; a
removed setting it cannot keep is refused and nothing is written."""

from __future__ import annotations

import dataclasses
import importlib.util
import json
import shutil
from pathlib import Path

import pytest
import torch
from safetensors import safe_open
from safetensors.torch import save

from sray.jobs.cli import main
from sray.model.semantic_ray import SRayModel
from sray.platform.checkpoints.folders import CheckpointManager, load_checkpoint, resolve_checkpoint
from sray.platform.checkpoints.model_loading import model_from_checkpoint
from sray.platform.config.held_out_render import HeldOutRender
from sray.platform.config.recipes import get_recipe
from sray.platform.config.train_config import load_job_config
from sray.platform.eval.segmenter import Segmenter, SegmenterConfig, load_segmenter, save_segmenter
from sray.platform.finetune.scene_artifacts import load_semantic_nerf
from sray.platform.migrate.config_formats import REMOVED_FIELDS
from sray.platform.sweep.prepare import read_sweep_record, reload_sweep
from sray.platform.train.state import build_training, restore_training

FIXTURE = Path(__file__).parent / "fixtures" / "sray_7734061"
FIXTURE_2 = Path(__file__).parent / "fixtures" / "sray_7966ddf"
CKPT = Path("job") / "checkpoints" / "step_000000002"
NERF = Path("fleet") / "scene0" / "semantic-nerf" / "semantic_nerf.safetensors"


def _builder():  # the 7734061 fixture's builder module: the probe inputs and tiny network of both fixtures
    spec = importlib.util.spec_from_file_location("make_fixture", FIXTURE / "make_fixture.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.fixture
def old_job(tmp_path: Path) -> Path:
    """A copy of the 7734061 job folder (the fixture itself stays as committed)."""
    shutil.copytree(FIXTURE, tmp_path / "old")
    return tmp_path / "old"


def _render(net: SRayModel) -> dict[str, torch.Tensor]:
    rgb, K, c2w, origins, dirs = _builder().probe_inputs()
    with torch.no_grad():
        fine = net.render_rays(net.encode(rgb, K, c2w), origins, dirs, 0.5, 3.0, stratified=False)["fine"]
    return {k: fine[k] for k in ("logits", "rgb", "depth")}


def _files(root: Path) -> dict[str, bytes]:
    return {str(p.relative_to(root)): p.read_bytes() for p in sorted(root.rglob("*")) if p.is_file()}


def test_an_old_job_is_refused_by_name_then_migrates_to_the_same_outputs(old_job: Path,
                                                                          capsys: pytest.CaptureFixture) -> None:
    for load in (lambda: model_from_checkpoint(old_job / CKPT), lambda: load_job_config(str(old_job), "job"),
                 lambda: resolve_checkpoint(old_job / "job")):
        with pytest.raises(ValueError, match=r"written by an earlier sray .*`sray migrate PATH`") as caught:
            load()
        assert "\n" not in str(caught.value) and str(old_job) in str(caught.value)
    assert main(["migrate", str(old_job)]) == 0
    assert "migrated checkpoint" in capsys.readouterr().out
    net, cfg = model_from_checkpoint(resolve_checkpoint(old_job / "job"))
    got, want = _render(net), torch.load(FIXTURE / "expected.pt", weights_only=True)
    for key in want:  # the same weights, the same network: bit for bit what 7734061 rendered
        torch.testing.assert_close(got[key], want[key], rtol=0, atol=0, msg=key)
    old_state = torch.load(FIXTURE / CKPT / "state.pt", weights_only=True)
    recipe = get_recipe("synth-demo")
    assert cfg.data.held_out == HeldOutRender(n_source=0, stride=2, render="fast", fast_stride=1, fast_confidence=0.9)
    assert (cfg.data.aug, cfg.optim, cfg.runtime) == (recipe.data.aug, recipe.optim, recipe.runtime)
    kept = {k: v for k, v in old_state["config"]["model"].items() if f"model.{k}" not in REMOVED_FIELDS}
    added = {f.name: f.default for f in dataclasses.fields(cfg.model) if f.name not in kept}  # fields since: defaults
    assert dataclasses.asdict(cfg.model) == kept | added
    assert load_job_config(str(old_job), "job") == cfg
    state = load_checkpoint(old_job / CKPT)
    assert state["counters"] == old_state["counters"] and state["best_metric"] == old_state["best_metric"]
    model, optimizer, scheduler = build_training(cfg)  # a resume reads the migrated state like a new one
    assert restore_training(state, model.net, optimizer, scheduler)[0] == 2
    assert main(["migrate", str(old_job)]) == 0  # once: a second run finds nothing to do
    assert "nothing to do" in capsys.readouterr().out


def test_the_older_layouts_7734061_still_read_migrate_too(old_job: Path) -> None:
    """Flat ``aug_<field>`` keys, runtime fields in the model section, the run section's fault settings, the
    training module's ``net.`` keys and no counters: what the shims of 7734061 read (``FLAT_AUG_PREFIX``,
    ``RUNTIME_FIELDS``, ``RETIRED_RUN_KEYS``, ``LEGACY_PREFIX``, the counters' fallbacks)."""
    path = old_job / CKPT / "state.pt"
    state = torch.load(path, weights_only=True)
    cfg = state["config"]
    cfg["data"].update({f"aug_{k}": v for k, v in cfg["data"].pop("aug").items()} | {"aug_colour_ev": 0.3})
    cfg["model"].update(cfg.pop("runtime") | {"chunk": 512})
    cfg["run"]["nan_at_step"] = 7
    state["model"] = {f"net.{k}": v for k, v in state["model"].items()}
    del state["counters"]
    torch.save(state, path)
    assert main(["migrate", str(old_job / CKPT)]) == 0
    net, migrated = model_from_checkpoint(old_job / CKPT)
    assert migrated.data.aug.colour_ev == 0.3 and migrated.runtime.chunk == 512
    torch.testing.assert_close(_render(net)["logits"], torch.load(FIXTURE / "expected.pt")["logits"], rtol=0, atol=0)
    counters = load_checkpoint(old_job / CKPT)["counters"]
    assert counters["cpu_seconds"] == 0.0 and counters["skipped_steps"] == 0
    assert counters["wall_seconds"] != counters["wall_seconds"]  # NaN: unknown for a checkpoint past step 0


@pytest.mark.parametrize(("section", "field", "value"), [("optim", "ema_decay", 0.998),
                                                         ("model", "encoder_norm", "group")])
def test_a_removed_setting_in_use_is_refused_in_one_line_and_nothing_is_written(
        old_job: Path, section: str, field: str, value: object, capsys: pytest.CaptureFixture) -> None:
    config = json.loads((old_job / "job" / "config.json").read_text())
    config[section][field] = value
    (old_job / "job" / "config.json").write_text(json.dumps(config))
    before = _files(old_job)
    assert main(["migrate", str(old_job)]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and f"{section}.{field} is {value!r}" in err and "7734061" in err
    assert _files(old_job) == before  # the checkpoint, which could migrate, was not written either


def test_a_path_holding_no_sray_artifact_is_refused(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    (tmp_path / "notes.txt").write_text("hello")
    assert main(["migrate", str(tmp_path)]) == 2
    assert main(["migrate", str(tmp_path / "notes.txt")]) == 2
    assert all("no sray artifact" in line or "not an artifact" in line
               for line in capsys.readouterr().err.strip().splitlines())


def test_a_sweep_record_and_a_segmenter_migrate(old_job: Path, tmp_path: Path) -> None:
    base = json.loads((old_job / "job" / "config.json").read_text())
    sweep = tmp_path / "sweep"
    sweep.mkdir()
    record = {"name": "s", "options": {}, "params": ["data.val_render=grid(fast, full)", "optim.ema_decay=choice(0.0)"],
              "plan": {"a": {"data.val_render": "fast", "optim.ema_decay": 0.0},
                       "b": {"data.val_render": "full", "optim.ema_decay": 0.0}},
              "base": base, "register_as": "", "tracker": "mlflow", "store": "", "format": "sray-sweep"}
    (sweep / "sweep.json").write_text(json.dumps(record))
    seg = save_segmenter(Segmenter(SegmenterConfig(n_classes=4, feat_dim=4, encoder_width=1)), {}, tmp_path / "seg")
    stored = json.loads((seg / "segmenter.json").read_text())
    stored["config"]["encoder_norm"] = "instance"
    (seg / "segmenter.json").write_text(json.dumps(stored))
    with pytest.raises(ValueError, match="sray migrate"):
        load_segmenter(seg)
    assert main(["migrate", str(tmp_path)]) == 0
    migrated = read_sweep_record(sweep)
    assert migrated.params == ["data.held_out.render=grid(fast, full)"]
    trials = reload_sweep(migrated, sweep).configs
    assert [t.data.held_out.render for t in trials] == ["fast", "full"]
    assert load_segmenter(seg)[1].config == SegmenterConfig(n_classes=4, feat_dim=4, encoder_width=1)
    assert CheckpointManager(old_job / "job" / "checkpoints").latest() is not None  # the job under tmp_path too


def test_a_fleet_record_without_a_tracker_name_is_refused_then_migrates(tmp_path: Path) -> None:
    """``fleet.json`` written before trackers had names: a re-launch refuses it, naming ``sray migrate``, which
    records the tracker its runs were made with (MLflow)."""
    from sray.platform.finetune.fleet import _fleet_record
    from sray.platform.tracking.mlflow_tracker import MlflowTracker

    tracker = MlflowTracker(f"sqlite:///{tmp_path / 'mlflow.db'}")
    (tmp_path / "fleet.json").write_text(json.dumps({"format": "sray-fleet", "base_sha256": "abc", "launches": 1,
                                                     "tracking_uri": tracker.store, "parent_run_id": "r1"}))
    with pytest.raises(ValueError, match="sray migrate"):
        _fleet_record(tmp_path, "abc", tracker)
    assert main(["migrate", str(tmp_path / "fleet.json")]) == 0
    assert _fleet_record(tmp_path, "abc", tracker)["tracker"] == "mlflow"


@pytest.fixture
def job_7966ddf(tmp_path: Path) -> Path:
    """A copy of the 7966ddf fixture (a job and a fleet's Semantic-NeRF artifact)."""
    shutil.copytree(FIXTURE_2, tmp_path / "old")
    return tmp_path / "old"


def _nerf_config(artifact: Path, **changes: object) -> None:
    """Rewrite the stored config of a Semantic-NeRF artifact with ``changes`` (its tensors as they were)."""
    with safe_open(str(artifact), framework="pt") as f:
        metadata, tensors = f.metadata(), {k: f.get_tensor(k) for k in f.keys()}
    artifact.write_bytes(save(tensors, metadata=metadata | {"config": json.dumps(json.loads(metadata["config"]) |
                                                                                 changes)}))


def test_a_7966ddf_job_and_scene_artifact_are_refused_then_migrate_to_the_same_outputs(
        job_7966ddf: Path, capsys: pytest.CaptureFixture) -> None:
    """Format-2 configs (``model.lambda_depth``, ``model.weight_margin``, ``data.aug.query_crop`` at their no-op values)
    and a Semantic-NeRF artifact with ``density_activation`` softplus: refused by name, migrated once, then bit for
    bit what 7966ddf rendered."""
    for load in (lambda: model_from_checkpoint(job_7966ddf / CKPT), lambda: load_job_config(str(job_7966ddf), "job"),
                 lambda: load_semantic_nerf(job_7966ddf / NERF)):
        with pytest.raises(ValueError, match=r"written by an earlier sray .*`sray migrate PATH`") as caught:
            load()
        assert "\n" not in str(caught.value) and str(job_7966ddf) in str(caught.value)
    assert main(["migrate", str(job_7966ddf)]) == 0
    migrated = {line.split(":")[0].removeprefix("[sray] migrated ") for line in capsys.readouterr().out.splitlines()}
    assert {"checkpoint", "job config", "Semantic-NeRF artifact"} <= migrated
    want = torch.load(FIXTURE_2 / "expected.pt", weights_only=True)
    net, cfg = model_from_checkpoint(job_7966ddf / CKPT)
    nerf = load_semantic_nerf(job_7966ddf / NERF)
    origins, dirs = _builder().probe_inputs()[3:]
    with torch.no_grad():
        got = {"sray": _render(net),
               "semantic-nerf": nerf.render_rays(origins, dirs, 0.5, 3.0, stratified=False)["fine"]}
    for model, outputs in want.items():
        for key in outputs:
            torch.testing.assert_close(got[model][key], outputs[key], rtol=0, atol=0, msg=f"{model} {key}")
    stored = json.loads((FIXTURE_2 / "job" / "config.json").read_text())
    assert dataclasses.asdict(cfg.model) == {k: v for k, v in stored["model"].items()
                                             if k not in ("lambda_depth", "weight_margin")} | {
        "weight_hidden": (4, 4), "geo_hidden": (8, 4), "class_weights": (), "semantic_cues": ()}
    assert dataclasses.asdict(cfg.data.aug) == {k: v for k, v in stored["data"]["aug"].items() if k != "query_crop"}
    assert load_job_config(str(job_7966ddf), "job") == cfg
    assert main(["migrate", str(job_7966ddf)]) == 0
    assert "nothing to do" in capsys.readouterr().out


@pytest.mark.parametrize(("where", "field", "value"), [("model", "lambda_depth", 0.1), ("data.aug", "query_crop", 0.5),
                                                       ("model", "weight_margin", 0.01),
                                                       ("nerf", "density_activation", "relu")])
def test_a_7966ddf_setting_in_use_is_refused_in_one_line_and_nothing_is_written(
        job_7966ddf: Path, where: str, field: str, value: object, capsys: pytest.CaptureFixture) -> None:
    if where == "nerf":
        _nerf_config(job_7966ddf / NERF, **{field: value})
        path = f"{field}"
    else:
        config = json.loads((job_7966ddf / "job" / "config.json").read_text())
        section = config
        for name in where.split("."):
            section = section[name]
        section[field] = value
        (job_7966ddf / "job" / "config.json").write_text(json.dumps(config))
        path = f"{where}.{field}"
    before = _files(job_7966ddf)
    assert main(["migrate", str(job_7966ddf)]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and f"{path} is {value!r}" in err and "use commit 7966ddf" in err
    assert str(job_7966ddf / (NERF if where == "nerf" else Path("job") / "config.json")) in err
    assert _files(job_7966ddf) == before
