"""The pieces of a stability point, each against an independent reference: which inputs a point shows a
method (clean levels shared, deterministic points once), the sources it picks against ``sray eval``'s, the
unseen fraction against OpenCV's projection, perturbed copies against the stored views, and the chart
panels and tables of a hand-made result."""

from __future__ import annotations

import sys
from pathlib import Path

import cv2
import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))
from train_fixtures import tiny_shards  # noqa: E402,F401

from sray.data_tools.loader.shard_loader import make_eval_samples  # noqa: E402
from sray.model.config import SRayConfig  # noqa: E402
from sray.platform.common.eval_protocol import EvalProtocol  # noqa: E402
from sray.platform.stability.axes import PRESETS, point_spec  # noqa: E402
from sray.platform.stability.report import level_stats, panels, write_outputs  # noqa: E402
from sray.platform.stability.rows import MODES, suite_rows  # noqa: E402
from sray.platform.stability.scene_points import training_views  # noqa: E402
from sray.platform.stability.stress_scenes import (choose_sources, load_scenes, perturbed_views,  # noqa: E402
                                                   unseen_fraction)
from sray.platform.stability.suite import planned_points  # noqa: E402

TOY = PRESETS["toy"]
SCENE = "synth_test_000"
ROWS = {r.name: r for r in suite_rows(["sray", "semantic-nerf", "2d-transfer"], list(MODES), SRayConfig(),
                                     SRayConfig())}
SRAY, NERF = ROWS["sray"], ROWS["semantic-nerf-scene"]


def test_clean_levels_share_one_spec_and_deterministic_points_are_planned_once() -> None:
    clean = {point_spec(axis, SRAY, level, 2, TOY).key() for axis, level in
             [("pose_noise", 0), ("blur", 1), ("jpeg", 100), ("occlusion", 0.0), ("precision", "fp32"),
              ("source_views", TOY.n_source)]}
    assert len(clean) == 1 and point_spec("pose_noise", SRAY, 0, 2, TOY).seed is None
    assert point_spec("pose_noise", SRAY, 5, 2, TOY).key() != point_spec("pose_noise", SRAY, 5, 1, TOY).key()
    nerf = point_spec("pose_noise", NERF, 0, 1, TOY)
    assert nerf.seed == 1 and nerf.n_views == 0  # a trained row's training draws from its seed even when clean
    tuned = point_spec("pose_noise", ROWS["sray-scene"], 0, 1, TOY)
    assert tuned.seed == 1 and tuned.n_views == TOY.n_source and tuned.key() != point_spec("pose_noise", SRAY, 0, 1,
                                                                                             TOY).key()
    planned = planned_points(TOY, ["pose_noise"], [SRAY, NERF])
    assert planned.count(("pose_noise", SRAY, 0, None)) == 1
    assert [p for p in planned if p[1] == SRAY and p[2] == 5] == [("pose_noise", SRAY, 5, s) for s in range(3)]
    assert len([p for p in planned if p[1] == NERF]) == 2 * TOY.seeds
    with pytest.raises(ValueError, match="does not stress"):
        point_spec("precision", ROWS["sray-scene"], "bf16", 0, TOY)
    with pytest.raises(ValueError, match="does not stress"):
        point_spec("unseen_rays", NERF, 4, 0, TOY)


def test_clean_sources_are_sray_evals_and_dropping_moves_down_the_ranking(tiny_shards) -> None:
    (scene,) = load_scenes(tiny_shards, [SCENE])
    clean = point_spec("pose_noise", SRAY, 0, 0, TOY)
    for sample in make_eval_samples(tiny_shards, SCENE, n_source=TOY.n_source):
        assert choose_sources(scene, sample.query_id, clean) == [
            v for v in scene.views[sample.query_id].neighbours.ids if v in scene.source_ids][:TOY.n_source]
    q = scene.test_ids[0]
    ranked = [v for v in scene.views[q].neighbours.ids if v in scene.pool_ids]
    far = point_spec("unseen_rays", SRAY, 4, 0, TOY)
    assert choose_sources(scene, q, far) == ranked[4:4 + TOY.unseen_n_source]
    with pytest.raises(ValueError, match="lower the level"):
        choose_sources(scene, q, point_spec("unseen_rays", SRAY, 15, 0, TOY))


def test_unseen_fraction_matches_opencv_projection(tiny_shards) -> None:
    from sray.data_tools.loader.samples import eval_sample
    from sray.model.view_render import strided_pixels

    (scene,) = load_scenes(tiny_shards, [SCENE])
    q = scene.test_ids[1]
    sample = eval_sample(scene.views, q, choose_sources(scene, q, point_spec("unseen_rays", SRAY, 4, 0, TOY)),
                         SCENE, scene.meta.near, scene.meta.far)
    h, w = sample.query_label.shape
    uv, _, _ = strided_pixels(h, w, 2)
    K, c2w = sample.query.K.double().numpy(), sample.query.c2w.double().numpy()
    # rays by hand: pixel -> camera direction with z = 1 -> world; samples at the bin centres of z-depth
    pix = np.concatenate([uv.double().numpy(), np.ones((len(uv), 1))], 1)
    dirs = (np.linalg.inv(K) @ pix.T).T @ c2w[:3, :3].T
    near, far = scene.meta.near, scene.meta.far
    z = np.repeat((near + (np.arange(6) + 0.5) * (far - near) / 6)[None], len(uv), 0)        # (R, 6) bin centres
    points = c2w[:3, 3] + z[..., None] * dirs[:, None, :]                                     # (R, N, 3)
    seen = np.zeros(points.shape[:2], bool)
    for K_s, c2w_s in zip(sample.sources.K.double().numpy(), sample.sources.c2w.double().numpy()):
        w2c = np.linalg.inv(c2w_s)
        rvec, _ = cv2.Rodrigues(w2c[:3, :3])
        proj, _ = cv2.projectPoints(points.reshape(-1, 3), rvec, w2c[:3, 3], K_s, None)
        proj = proj.reshape(*points.shape[:2], 2)
        depth = (points @ w2c[:3, :3].T + w2c[:3, 3])[..., 2]
        inside = (proj[..., 0] >= -0.5) & (proj[..., 0] <= w - 0.5) & (proj[..., 1] >= -0.5) & (proj[..., 1] <= h - 0.5)
        seen |= inside & (depth > 1e-3)
    assert unseen_fraction(sample, 2, 6, 1e-3) == pytest.approx(1 - seen.mean(), abs=1e-12)


def test_perturbed_copies_touch_only_their_views_with_common_random_numbers(tiny_shards) -> None:
    (scene,) = load_scenes(tiny_shards, [SCENE])
    ids = scene.source_ids[:3]
    weak = perturbed_views(scene, ids, "occlusion", 0.2, seed=4)
    strong = perturbed_views(scene, ids, "occlusion", 0.4, seed=4)
    for v, view in weak.items():
        if v not in ids:
            assert view is scene.views[v]
    for v in ids:
        clean, a, b = scene.views[v].rgb(), weak[v].rgb(), strong[v].rgb()
        hidden_a, hidden_b = (a != clean).any(-1), (b != clean).any(-1)
        assert hidden_a.mean() <= 0.2 + 1e-9 and hidden_b.mean() > hidden_a.mean()
        np.testing.assert_array_equal(weak[v].c2w, scene.views[v].c2w)
    again = perturbed_views(scene, ids, "occlusion", 0.2, seed=4)
    assert all(again[v].rgb_png == weak[v].rgb_png for v in ids)
    moved = perturbed_views(scene, ids, "pose_noise", 3.0, seed=1)
    for v in ids:
        rel = moved[v].c2w[:3, :3] @ scene.views[v].c2w[:3, :3].T
        assert np.degrees(np.arccos(np.clip((np.trace(rel) - 1) / 2, -1, 1))) == pytest.approx(3.0, abs=1e-6)


def test_training_views_spread_over_the_pool() -> None:
    pool = [f"v{i}" for i in range(16)]
    assert training_views(pool, 0) == pool and training_views(pool, 99) == pool
    assert training_views(pool, 1) == ["v8"] and training_views(pool, 2) == ["v0", "v15"]
    assert training_views(pool, 4) == ["v0", "v5", "v10", "v15"]


def _record(axis, method, level, seed, miou, psnr=20.0, x=None) -> dict:
    ok = miou is not None
    return {"axis": axis, "method": method, "level": level, "seed": seed, "status": "ok" if ok else "failed",
            "miou": miou, "psnr": psnr if ok else None, "x": (level if x is None else x) if ok else None,
            "error": None if ok else "NonFiniteOutput: 3 rendered rays are not finite", "key": "k"}


def test_chart_panels_and_tables_of_a_known_result(tmp_path) -> None:
    nerf = NERF.name
    records = [_record("blur", "sray", 1, None, 60.0, 25.0),
               *(_record("blur", "sray", 7, s, m, p)
                 for s, m, p in [(0, 40.0, 20.0), (1, 50.0, 22.0), (2, 30.0, 18.0)]),
               *(_record("blur", nerf, lvl, s, m) for lvl, m in [(1, 70.0), (7, None)] for s in range(3)),
               _record("unseen_rays", "sray", 0, None, 60.0, x=0.05),
               _record("unseen_rays", "sray", 4, None, 20.0, x=0.4)]
    (blur, unseen) = panels(level_stats(records), ["blur", "unseen_rays"], "miou")
    sray = blur.lines["sray"]
    assert [(p.x, p.mean, p.low, p.high) for p in sray] == [(1.0, 60.0, 60.0, 60.0), (7.0, 40.0, 30.0, 50.0)]
    assert [(p.x, p.mean) for p in blur.lines[nerf]] == [(1.0, 70.0), (7.0, None)]
    assert [(p.x, p.mean) for p in unseen.lines["sray"]] == [(0.05, 60.0), (0.4, 20.0)]
    (psnr_blur,) = panels(level_stats(records), ["blur"], "psnr")
    assert [(p.mean, p.low, p.high) for p in psnr_blur.lines["sray"]][1] == (20.0, 18.0, 22.0)
    protocols = {"sray": EvalProtocol("a rule v1", TOY.n_source, TOY.eval_stride),
                 nerf: EvalProtocol.without_sources(4)}
    out = write_outputs(records, TOY, ["blur", "unseen_rays"], [SRAY, NERF], protocols, tmp_path, {})
    table = out["tables"]["blur"]
    assert table.startswith("| motion-blur length (px) | sray (never saw the scene, RGB) mIoU % (min-max) | ")
    assert "| semantic-nerf-scene (trained on the scene, RGB) mIoU % (min-max) |" in table
    assert "| 1 | 60.00 (60.0-60.0) | 25.00 | 70.00 (70.0-70.0) | 20.00 |" in table
    assert "| 7 | 40.00 (30.0-50.0) | 20.00 | failed | failed |" in table
    assert "0 → 5.0 %, 4 → 40.0 %" in out["tables"]["unseen_rays"]
    assert f"blur / {nerf}: half the clean mIoU lost at 4 (interpolated between levels)" in out["breaking"]
    assert ("blur / sray: keeps half its clean mIoU at every level tested (mIoU stays above 30.0, half of the "
            "clean 60.0)") in out["breaking"]
    assert all(c.stat().st_size > 10_000 for c in out["charts"])


def test_preset_world_pretrains_each_model_once_and_reuses_it(tmp_path, monkeypatch) -> None:
    from types import SimpleNamespace

    from sray.jobs.stability import world

    seen = []

    def fake_launch(cfg):
        seen.append((cfg.model.attention, cfg.optim.steps, cfg.model.n_coarse, cfg.run.experiment))
        folder = tmp_path / cfg.run.name
        folder.mkdir()
        return SimpleNamespace(best_checkpoint=folder, latest_checkpoint=folder)

    def fake_segmenter(shards, cpu_seconds, out, **kwargs):
        seen.append(("segmenter", cpu_seconds))
        Path(out).mkdir(parents=True)

    monkeypatch.setattr(world, "launch_training", fake_launch)
    monkeypatch.setattr(world, "train_segmenter", fake_segmenter)
    first = world.world_models(TOY, tmp_path / "shards", tmp_path, "sqlite:///x.db")
    w = TOY.world
    assert seen == [("full", w.pretrain_steps, w.n_coarse, "sray-stability"),
                    ("none", w.pretrain_steps, w.n_coarse, "sray-stability"), ("segmenter", w.segmenter_cpu_seconds)]
    assert world.world_models(TOY, tmp_path / "shards", tmp_path, "sqlite:///x.db") == first
    assert len(seen) == 3 and first.segmenter == tmp_path / "world" / "segmenter"


def test_points_are_reused_only_under_the_same_preset_and_models(tmp_path) -> None:
    import dataclasses

    from sray.platform.stability.points_study import DEFINITION_FILE, check_definition
    from sray.platform.stability.rows import SuiteModels

    study = tmp_path / "study"
    check_definition(study, TOY, SuiteModels(tmp_path / "c"))
    check_definition(study, TOY, SuiteModels(tmp_path / "c", segmenter=tmp_path / "s"))  # a model added later
    assert (study / DEFINITION_FILE).exists()
    changed = dataclasses.replace(TOY, eval_stride=TOY.eval_stride * 2)
    with pytest.raises(ValueError, match="another definition of preset 'toy'; use a new --out"):
        check_definition(study, changed, SuiteModels(tmp_path / "c"))
    with pytest.raises(ValueError, match=r"other models as \['segmenter'\]"):
        check_definition(study, TOY, SuiteModels(tmp_path / "c", segmenter=tmp_path / "other"))


def test_point_records_come_from_the_study_and_an_errored_trial_is_a_failed_point(tmp_path) -> None:
    """Each planned point reads its spec's trial: finished -> its result, errored -> failed with the error,
    missing -> no records (the axis is not complete)."""
    from sray.platform.stability.points_study import point_records, study_folder, study_plan
    from sray.platform.sweep.study import FINISHED, TrialRecord, trial_folder, write_record

    planned = planned_points(TOY, ["exposure"], [SRAY])
    plan = study_plan(TOY, planned)
    assert len(plan) == 1 + TOY.seeds  # the clean point once, the perturbed level per seed
    study = study_folder(tmp_path, TOY)
    clean, *seeded = plan
    ok = {"status": "ok", "miou": 40.0, "psnr": 20.0, "error": None}
    for key in (clean, *seeded[:-1]):
        write_record(trial_folder(study, key), TrialRecord(outcome=FINISHED, result=ok))
    assert point_records(tmp_path, TOY, planned) is None  # the last seed is missing
    assert point_records(tmp_path, TOY, planned, {seeded[-1]: "RayActorError: died"})[-1]["error"] == \
        "RayActorError: died"
    (trial_folder(study, seeded[-1])).mkdir(parents=True)
    write_record(trial_folder(study, seeded[-1]), TrialRecord([1.0], "errored", "MemoryError: out"))
    records = point_records(tmp_path, TOY, planned)
    assert [(r["level"], r["seed"], r["status"], r["miou"]) for r in records] == \
        [(0, None, "ok", 40.0), (2, 0, "ok", 40.0), (2, 1, "ok", 40.0), (2, 2, "failed", None)]
    assert records[-1]["error"] == "MemoryError: out" and records[0]["x"] == 0.0 and records[-1]["x"] is None
