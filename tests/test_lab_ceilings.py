"""``sray lab ceilings`` end to end on exactly consistent fixture scenes with an untrained tiny checkpoint, its
rows against stand-ins and hand counts, and ``sray lab view-weights``."""

from __future__ import annotations

import json
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
import torch
from ceilings_fixtures import shards  # noqa: F401
from fleet_fixtures import one_thread  # noqa: F401
from train_fixtures import tiny_config

from sray.data_tools.loader.augment import Augmentation
from sray.data_tools.loader.shard_loader import make_eval_samples
from sray.data_tools.loader.views import read_scene_views
from sray.data_tools.scene import SceneMeta
from sray.data_tools.shards.manifest import read_manifest
from sray.jobs.cli import main
from sray.lab.ceilings import measure as ceilings
from sray.lab.ceilings.measure import source_ids
from sray.lab.ceilings.report import HELD_OUT_TITLE, REPORT_FILE, TITLE
from sray.lab.ceilings.rows import CeilingRow
from sray.lab.ceilings.surface_field import field_at_surface
from sray.lab.studies.spec import load_study
from sray.lab.view_weights import report as view_weights
from sray.model.config import SRayConfig
from sray.model.runtime import Runtime
from sray.platform.eval.label_transfer import UNSEEN, transfer_labels
from sray.platform.eval.segmenter_training import train_segmenter
from sray.platform.eval.zero_shot import training_scenes
from sray.platform.train.state import write_initial_checkpoint

REPO = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def segmenter(shards: Path, tmp_path_factory: pytest.TempPathFactory, one_thread: None) -> Path:  # noqa: F811
    """A segmenter trained for half a CPU second."""
    out = tmp_path_factory.mktemp("segmenter")
    train_segmenter(shards, 0.5, out, seed=0, augment=Augmentation(min_source=2), n_source=3, top_k=8,
                    progress=False)
    return out


def test_rows_run_end_to_end_and_the_oracle_transfer_is_near_perfect(shards: Path, segmenter: Path, tmp_path: Path,
                                                                     one_thread: None) -> None:  # noqa: F811
    """``sray lab ceilings`` scores every row on the test scene's two test views with an untrained checkpoint;
    the ground-truth transfer on exactly consistent scenes labels nearly every covered pixel right; oracle rows
    are marked; the JSON, the table and the document section are written."""
    cfg = tiny_config(shards, tmp_path)
    checkpoint = write_initial_checkpoint(cfg, tmp_path / "job" / "checkpoints" / "step_000000000")
    doc = tmp_path / "benchmarks.md"
    assert main(["lab", "ceilings", "--checkpoint", str(checkpoint), "--data", str(shards), "--n-source", "4",
                 "--segmenter", str(segmenter), "--probe-steps", "10", "--probe-views", "8",
                 "--out", str(tmp_path / "out"), "--doc", str(doc)]) == 0
    rows = {r["key"]: r for r in json.loads((tmp_path / "out" / REPORT_FILE).read_text())["rows"]}
    assert list(rows) == ["a", "b", "c", "c-rgb", "s", "d", "e", "e-seg", "e-rand", "f", "f-src"]
    assert {k for k, r in rows.items() if r["oracle"]} == {"a", "b", "d"}
    assert all(r["views"] == 2 and r["seconds_per_view"] > 0 and 0 <= r["miou"] <= 1
               for k, r in rows.items() if k != "f-src")
    # f-src scores each source view of the test scene once: the 2 queries' 4 sources each, some shared
    assert 4 <= rows["f-src"]["views"] <= 8 and 0 <= rows["f-src"]["miou"] <= 1
    assert all(rows[k]["coverage"] is None for k in ("s", "e", "e-seg", "e-rand", "f", "f-src"))
    assert rows["f"]["protocol"]["inputs"] == "cameras, query image, segmenter"
    assert 0.5 < rows["a"]["coverage"] <= 1 and rows["b"]["coverage"] == rows["a"]["coverage"]
    assert 0 < rows["c"]["coverage"] <= 1 and 0 < rows["c-rgb"]["coverage"] <= 1
    # the RGB row reads S-Ray's rendered depth, never the query's ground truth or the sources' depth
    assert rows["c-rgb"]["protocol"]["inputs"] == "cameras, source images, segmenter, S-Ray rendered query depth"
    assert rows["s"]["protocol"]["inputs"] == "cameras, source images"
    assert "depth: checkpoint step 0, fast (pixel stride 1" in rows["c-rgb"]["budget"]
    hour = load_study(REPO / "jobs" / "studies" / "hour-recipe.yaml")  # rows s and c-rgb render as the studies score
    assert (ceilings.ZERO_SHOT_RENDER.pixel_stride, ceilings.ZERO_SHOT_RENDER.confidence) == hour.eval_fast
    assert rows["a"]["acc_on_covered"] > 0.97, rows["a"]
    assert rows["a"]["total_acc"] >= 0.97 * rows["a"]["coverage"]
    assert rows["a"]["miou"] > 0.5
    assert "segmenter" in rows["b"]["budget"] and "steps" in rows["c"]["budget"]
    text = doc.read_text()
    assert text.count("## Ceilings") == 1 and "**oracle**" in text and "reads the query image" in text


def test_held_out_rows_score_the_first_training_scenes_held_out_views(shards: Path, tmp_path: Path,
                                                                      one_thread: None) -> None:  # noqa: F811
    """``--held-out 1`` scores every held-out (``test``-split) view of the first training scene by name instead of
    the unseen test scene, the oracle transfer near perfect there too; its table gets its own title, so the
    zero-shot table stays beside it; a held-out count below 1 is refused with exit code 2."""
    assert training_scenes(shards, 5) == ["a", "b"] and training_scenes(shards, 1) == ["a"]
    checkpoint = write_initial_checkpoint(tiny_config(shards, tmp_path), tmp_path / "job" / "step_000000000")
    doc = tmp_path / "benchmarks.md"
    common = ["lab", "ceilings", "--checkpoint", str(checkpoint), "--data", str(shards), "--n-source", "4",
              "--probe-steps", "2", "--probe-views", "4", "--doc", str(doc)]
    assert main([*common, "--views-per-scene", "1", "--out", str(tmp_path / "zero-shot")]) == 0
    assert main([*common, "--held-out", "1", "--out", str(tmp_path / "held")]) == 0
    report = json.loads((tmp_path / "held" / REPORT_FILE).read_text())
    held_views = read_manifest(shards).scenes["a"].meta["splits"]["test"]
    assert report["scenes"] == ["a"] and report["held_out"] == 1 and "train split" in report["source_rule"]
    rows = {r["key"]: r for r in report["rows"]}
    assert all(r["views"] == len(held_views) == 2 for r in rows.values())
    assert rows["a"]["acc_on_covered"] > 0.97 and rows["a"]["coverage"] > 0.5
    text = doc.read_text()
    assert f"### {HELD_OUT_TITLE}" in text and f"### {TITLE}" in text and "1 training scene(s)" in text
    assert main([*common, "--held-out", "-1", "--out", str(tmp_path / "bad")]) == 2
    with pytest.raises(ValueError, match="held-out training scenes"):
        training_scenes(shards, 0)


@pytest.mark.parametrize("fine_samples", ["new", "union"])
def test_the_field_is_read_at_the_ground_truth_depth(fine_samples: str) -> None:
    """A stand-in fine field that scores class c only at a sample exactly at depth c (class 0 otherwise) is read at
    the sample that is the ground-truth depth: the prediction is the depth itself, UNSEEN where it is unknown; the
    bracket it is given is sorted, holds n_fine samples around the surface (plus the coarse centres with union); the
    field runs the runtime's implementation, in chunks of its rays."""
    cfg = SRayConfig(n_classes=6, n_coarse=4, n_fine=6, fine_samples=fine_samples)
    seen_z: list[torch.Tensor] = []

    def fine(src: object, origins: torch.Tensor, dirs: torch.Tensor, z: torch.Tensor, lo: torch.Tensor,
             hi: torch.Tensor, impl: str) -> dict[str, torch.Tensor]:
        assert impl == "reference"
        seen_z.append(z)
        return {"logits": ((z[..., None] - torch.arange(6.0)).abs() < 1e-6).float()}

    depth = torch.tensor([[1.0, 2.0, 0.0], [3.0, 4.0, 5.0], [2.0, 0.0, 1.0]])
    K = torch.tensor([[3.0, 0.0, 1.0], [0.0, 3.0, 1.0], [0.0, 0.0, 1.0]])
    net = SimpleNamespace(cfg=cfg, fine=fine)
    pred = field_at_surface(net, SimpleNamespace(feats=torch.zeros(1)), K, torch.eye(4), depth, 0.5, 6.0,
                            Runtime(impl="reference", chunk=5))
    torch.testing.assert_close(pred, torch.where(depth > 0, depth.long(), torch.full_like(pred, UNSEEN)))
    z = torch.cat(seen_z)
    assert z.shape == (7, 6 + (4 if fine_samples == "union" else 0)) and bool((z.diff(dim=-1) >= 0).all())


def test_row_s_scores_the_render_and_row_c_rgb_carries_the_segmenter_by_its_depth(
        shards: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A stand-in S-Ray whose render returns the query's ground-truth labels as logits and a depth map, and a
    stand-in segmenter that returns the sources' true labels: row s scores the render's argmax (mIoU 1); row c-rgb
    is the backward transfer, without source depth, of the segmenter's labels by the rendered depth; given the true
    depth it covers at least what the occlusion-tested oracle row a covers, and given a depth 0 nowhere it sees
    nothing."""
    sample = next(iter(make_eval_samples(shards, "t", split="test", n_source=3)))
    views = read_scene_views(shards, read_manifest(shards).scenes["t"])
    meta = SceneMeta.from_json(read_manifest(shards).scenes["t"].meta)
    ids = source_ids(sample, views, meta, 3)
    gt_sources = torch.from_numpy(np.stack([views[i].label() for i in ids]).astype(np.int64))
    cfg = SRayConfig(n_classes=int(sample.query_label.max()) + 1)
    monkeypatch.setattr(ceilings, "encode_sources", lambda net, sample, device: None)
    monkeypatch.setattr(ceilings, "field_at_surface", lambda *args: sample.query_label.clone())
    gt = sample.query_label.long()
    for depth, total in ((sample.query_depth, None), (torch.zeros_like(sample.query_depth), 0)):
        logits = torch.nn.functional.one_hot(gt.clamp(0, cfg.n_classes - 1), cfg.n_classes).float()
        net = SimpleNamespace(cfg=cfg, render_image=lambda *args, fast=None: {"fine": {"logits": logits,
                                                                                        "depth": depth}})
        # the true labels of whichever images it is given: the sources, or the query alone
        segmenter = SimpleNamespace(predict=lambda rgb: gt_sources if rgb.shape[0] == len(ids) else gt[None])
        scorer = ceilings.ViewScorer(net, segmenter, {}, 0.05, ceilings.ZERO_SHOT_RENDER)
        rows = {k: CeilingRow(k, t, p, geometric=p.geometry != "—")
                for k, t, p in ceilings.row_descriptors(True, False) if not k.startswith("e")}
        scorer.score(rows, sample, gt_sources, ids)
        scorer.score({**rows, **{k: CeilingRow(k, "", r.protocol, geometric=r.geometric) for k, r in rows.items()
                                 if k != "f-src"}}, sample, gt_sources, ids)  # the same sources: none scored twice
        assert rows["f"].summary(cfg.n_classes)["miou"] == 1.0 and rows["f"].views == 1
        assert rows["f-src"].views == len(ids) and rows["f-src"].summary(cfg.n_classes)["total_acc"] == 1.0
        expected = transfer_labels(gt_sources, sample.sources.K, sample.sources.c2w, None, sample.query.K,
                                   sample.query.c2w, tuple(gt.shape), "backward", ignore_id=cfg.ignore_id,
                                   query_depth=depth)
        scored = rows["c-rgb"].summary(cfg.n_classes)
        assert rows["c-rgb"].covered == int((expected.seen & (gt != cfg.ignore_id)).sum())
        assert rows["s"].summary(cfg.n_classes)["miou"] == 1.0
        if total is None:
            assert rows["c-rgb"].covered >= rows["a"].covered > 0 and scored["miou"] > 0.5
        else:
            assert rows["c-rgb"].covered == total and scored["total_acc"] == 0.0
    # a segmenter that says one class everywhere: f-src's scores against a hand count of the sources' labels
    labelled = gt_sources[gt_sources != cfg.ignore_id]
    const = int(torch.mode(labelled).values)
    scorer = ceilings.ViewScorer(net, SimpleNamespace(predict=lambda rgb: torch.full((rgb.shape[0], *rgb.shape[-2:]),
                                                                                     const)),
                                 {}, 0.05, ceilings.ZERO_SHOT_RENDER)
    rows = {k: CeilingRow(k, t, p, geometric=p.geometry != "—") for k, t, p in ceilings.row_descriptors(True, False)
            if not k.startswith("e")}
    scorer.score(rows, sample, gt_sources, ids)
    share = float((labelled == const).double().mean())
    f_src = rows["f-src"].summary(cfg.n_classes)
    assert f_src["total_acc"] == pytest.approx(share)
    assert f_src["miou"] == pytest.approx(share / len(torch.unique(labelled)))  # IoU of `const`, 0 for the rest
    fresh = {k: CeilingRow(k, t, p, geometric=p.geometry != "—") for k, t, p in ceilings.row_descriptors(True, False)
             if not k.startswith("e")}
    with pytest.raises(ValueError, match="source view ids for"):  # refused before any row is scored
        scorer.score(fresh, sample, gt_sources, ids[:-1])
    assert all(row.views == 0 for row in fresh.values())


def test_view_weights_rows_run_end_to_end_and_plain_mean_weights_read_as_blind(shards: Path, tmp_path: Path,
                                                                               one_thread: None) -> None:  # noqa: F811
    """``sray lab view-weights`` on two untrained checkpoints of the fixture scenes (whose box hides the wall
    from some sources): with tau = 1 every valid view weighs exactly the plain mean (n w = 1, ranking 0.5, the
    occluded mass the plain mean's, nothing removable, no spread); with tau = 0.7 the weights
    spread within C(tau) and the occluded mass stays at or above its floor; both rows count the same points; the JSON
    and the table in the document's Ceilings section are written."""
    paths = []
    for name, tau in (("mean", 1.0), ("occl", 0.7)):
        cfg = tiny_config(shards, tmp_path)
        cfg.model.tau = tau
        paths.append(str(write_initial_checkpoint(cfg, tmp_path / name / "checkpoints" / "step_000000000")))
    doc = tmp_path / "benchmarks.md"
    assert main(["lab", "view-weights", "--checkpoint", *paths, "--data", str(shards), "--n-source", "4",
                 "--views-per-scene", "2", "--stride", "2", "--out", str(tmp_path / "out"), "--doc", str(doc)]) == 0
    mean, occl = json.loads((tmp_path / "out" / view_weights.REPORT_FILE).read_text())
    assert mean["points"] == occl["points"] > 0 and mean["pairs"] > 0, "the fixture's box occludes some sources"
    assert mean["visible_relative_weight"] == pytest.approx(1.0) == mean["occluded_relative_weight"]
    assert mean["ranking"] == 0.5 and mean["removed_share"] is None and mean["relative_weight_sd"] < 1e-6
    assert mean["occluded_mass"] == pytest.approx(mean["occluded_mass_plain"])
    assert occl["tau"] == 0.7 and occl["relative_weight_sd"] > 0
    assert 0.7 < occl["occluded_relative_weight"] < 1 / 0.7 and 0.7 < occl["visible_relative_weight"] < 1 / 0.7
    assert occl["occluded_mass"] >= occl["occluded_mass_floor"] - 1e-6
    assert 0 <= occl["acc_occluded"] <= 1 and 0 <= occl["acc_clear"] <= 1
    text = doc.read_text()
    assert text.count("## Ceilings") == 1 and f"### {view_weights.TITLE}" in text and "`occl/step_000000000`" in text
