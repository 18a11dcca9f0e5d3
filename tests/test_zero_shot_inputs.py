"""Zero-shot evaluation uses only what a user has at test time.

A test view of an unseen scene is known to the user by its pose and intrinsics alone; its depth,
labels and colours are the ground truth it is scored against. Rewriting them on disk and running the
pipeline again (convert -> shard -> eval loader -> model) must leave its ranked source views, the
scene's near/far and every model input unchanged. Rewriting a SOURCE view's depth must change the
bounds and the ranking, so these tests can fail.
"""

from __future__ import annotations

import shutil
from dataclasses import asdict, dataclass
from pathlib import Path

import cv2
import numpy as np
import pytest
import scene_fixtures
import torch
from source_writers import write_replica

from sray.data_tools.label_spaces import SCANNET20
from sray.data_tools.loader.sample_types import EvalSample
from sray.data_tools.loader.shard_loader import make_eval_samples
from sray.data_tools.loader.views import read_scene_views
from sray.data_tools.readers.convert import ConvertConfig, convert_scene
from sray.data_tools.readers.replica import replica_intrinsics
from sray.data_tools.scene import Scene, SceneMeta, View, depth_bounds
from sray.data_tools.scene_folder import read_scene
from sray.data_tools.shards.manifest import read_manifest
from sray.data_tools.shards.writer import write_shards
from sray.data_tools.synth.dataset import generate_scene
from sray.model.config import SRayConfig
from sray.model.rays import pixel_rays
from sray.model.semantic_ray import SRayModel

H, W, N_VIEWS, SCENE = 36, 48, 20, "unseen"


@dataclass
class Run:
    """What one convert + shard run of the test scene produced."""

    meta: SceneMeta
    """The converted scene's metadata (near/far measured by ``convert``)."""
    manifest_bounds: tuple[float, float]
    """near/far of the scene in the shards' manifest."""
    ranked: dict[str, tuple[list[str], list[float]]]
    """Stored neighbour ids and scores of each test view, from the shards."""
    samples: list[EvalSample]
    """The eval loader's samples of the test split (4 sources each)."""


def room_sequence(dst: Path) -> Path:
    """The box room of ``scene_fixtures`` seen through the Replica layout's 90° camera from 20 views
    on an arc, written as a Replica sequence at ``dst``."""
    K = replica_intrinsics((H, W))
    views = []
    for i, c2w in enumerate(scene_fixtures.random_cameras(N_VIEWS, seed=3)):
        rgb, depth, label = scene_fixtures.render(K, c2w, H, W)
        views.append(View(f"v{i}", rgb, depth, label, K.copy(), c2w))
    meta = SceneMeta("room", "scannet20", list(SCANNET20), [v.view_id for v in views], {})
    return write_replica(Scene.in_memory(meta, views), dst)


def run_pipeline(src: Path, root: Path) -> Run:
    """Convert ``src`` as a test scene (window = all 20 frames), shard it, read back what zero-shot uses."""
    report = convert_scene(ConvertConfig(format="replica", src=src, out=root / "scenes", name=SCENE, role="test",
                                         frame_skip=1, window_start=0))
    write_shards(root / "scenes", root / "shards", views_per_shard=8, neighbours=16, progress=False)
    meta = read_scene(report.scene_dir).meta
    entry = read_manifest(root / "shards").scenes[SCENE]
    stored = read_scene_views(root / "shards", entry)
    ranked = {q: (stored[q].neighbours.ids, stored[q].neighbours.scores) for q in meta.splits["test"]}
    samples = list(make_eval_samples(root / "shards", SCENE, "test", n_source=4))
    return Run(meta, (entry.meta["near"], entry.meta["far"]), ranked, samples)


def overwrite_frame(src: Path, frame: int, depth_m: float, with_labels_and_colour: bool) -> None:
    """Replace a Replica frame's depth by a constant (and optionally its labels and colours) with OpenCV."""
    assert cv2.imwrite(str(src / "depth" / f"depth_{frame}.png"), np.full((H, W), round(depth_m * 1000), np.uint16))
    if with_labels_and_colour:
        assert cv2.imwrite(str(src / "semantic_class" / f"semantic_class_{frame}.png"), np.full((H, W), 7, np.uint8))
        assert cv2.imwrite(str(src / "rgb" / f"rgb_{frame}.png"), np.zeros((H, W, 3), np.uint8))


@pytest.fixture(scope="module")
def runs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Run]:
    """The pipeline on the original sequence, with every test view's depth (0.2 m), labels (all 'table')
    and colours (black) rewritten, and with one source view's depth rewritten (0.3 m)."""
    root = tmp_path_factory.mktemp("zero_shot")
    original = room_sequence(root / "original")
    out = {"original": run_pipeline(original, root / "run_original")}
    meta = out["original"].meta
    assert len(meta.view_ids) == N_VIEWS  # window 0..19 of frames 0..19: view i is frame i
    for name in ("test_rewritten", "source_rewritten"):
        shutil.copytree(original, root / name)
    for q in meta.splits["test"]:
        overwrite_frame(root / "test_rewritten", meta.view_ids.index(q), 0.2, with_labels_and_colour=True)
    top_source = out["original"].ranked[meta.splits["test"][0]][0][0]
    overwrite_frame(root / "source_rewritten", meta.view_ids.index(top_source), 0.3, with_labels_and_colour=False)
    for name in ("test_rewritten", "source_rewritten"):
        out[name] = run_pipeline(root / name, root / f"run_{name}")
    return out


def test_test_view_ground_truth_changes_no_source_ranking_and_no_bound(runs: dict[str, Run]) -> None:
    """Ranked source ids and scores of every test view, and near/far (scene.json and manifest), are unchanged."""
    before, after = runs["original"], runs["test_rewritten"]
    assert after.ranked == before.ranked
    assert (after.meta.near, after.meta.far) == (before.meta.near, before.meta.far)
    assert after.manifest_bounds == before.manifest_bounds == (before.meta.near, before.meta.far)
    assert all(len(ids) == 16 and set(ids) <= set(before.meta.splits["source"] + before.meta.splits["finetune"])
               for ids, _ in before.ranked.values())


def test_source_view_depth_does_change_bounds_and_ranking(runs: dict[str, Run]) -> None:
    """The control: a source view's depth feeds near/far and the test views' ranking."""
    before, after = runs["original"], runs["source_rewritten"]
    assert after.meta.near < before.meta.near and after.meta.near == pytest.approx(0.3 * 0.9)
    assert after.ranked != before.ranked


def test_model_inputs_and_prediction_are_unchanged(runs: dict[str, Run]) -> None:
    """Every tensor the model sees is bit-identical, while the targets did change; a tiny random S-Ray
    model renders the same logits for each test view."""
    before, after = runs["original"].samples, runs["test_rewritten"].samples
    assert [s.query_id for s in before] == [s.query_id for s in after] == runs["original"].meta.splits["test"]
    torch.manual_seed(0)
    model = SRayModel(SRayConfig(n_classes=len(SCANNET20), feat_dim=8, n_coarse=8, n_fine=8, n_source=4)).eval()
    for b, a in zip(before, after):
        torch.testing.assert_close(_model_inputs(a), _model_inputs(b), atol=0, rtol=0, msg=b.query_id)
        assert not torch.equal(a.query_label, b.query_label) and not torch.equal(a.query_depth, b.query_depth)
        logits = [_render_logits(model, s) for s in (b, a)]
        torch.testing.assert_close(logits[1], logits[0], atol=0, rtol=0)


def _model_inputs(sample: EvalSample) -> dict:
    """Everything of an evaluation sample the model sees: source views, query camera, bounds."""
    return {"sources": asdict(sample.sources), "query": asdict(sample.query), "near": sample.near, "far": sample.far}


def _render_logits(model: SRayModel, sample: EvalSample) -> torch.Tensor:
    """Fine-pass semantic logits (R, L) of a 5 x 5 grid of the query's pixels, deterministic sampling."""
    v, u = torch.meshgrid(torch.linspace(0, H - 1, 5), torch.linspace(0, W - 1, 5), indexing="ij")
    origins, dirs = pixel_rays(sample.query.K, sample.query.c2w, torch.stack([u, v], -1).reshape(-1, 2))
    with torch.no_grad():
        src = model.encode(sample.sources.rgb, sample.sources.K, sample.sources.c2w)
        out = model.render_rays(src, origins, dirs, sample.near, sample.far, stratified=False)
    return out["fine"]["logits"]


@pytest.mark.parametrize("role", ["test", "train"])
def test_generated_scene_bounds_use_the_pool_of_a_test_scene(role: str) -> None:
    """Procedural scenes: a test scene's near/far are the bounds of its source and finetune views' depth
    (views picked here from the splits), a train scene's those of all its views."""
    scene = generate_scene("g", 5, N_VIEWS, 24, 32, role)
    splits = scene.meta.splits
    chosen = splits["source"] + splits["finetune"] if role == "test" else scene.meta.view_ids
    assert (scene.meta.near, scene.meta.far) == depth_bounds([scene.read_view(v).depth for v in chosen])
