"""``sray label`` and ``sray.load``: the three imports of one procedural room (nerfstudio, COLMAP text, COLMAP
binary) label alike; the command's files hold the API's outputs; no frame is its own source; on a labelled scene
the scores match a confusion matrix counted by hand from the written label maps; unlabelled captures pass
``sray data check`` and ``sray data shard`` and training refuses them."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
from capture_writers import write_colmap, write_nerfstudio
from fleet_fixtures import one_thread, tiny_checkpoint  # noqa: F401  (pytest fixtures, used by name)
from mlflow import MlflowClient
from mlflow_fixtures import mlflow_template  # noqa: F401
from scene_fixtures import make_scene
from train_fixtures import tiny_shards  # noqa: F401

import sray
from sray.data_tools.check.scenes import check_dataset
from sray.data_tools.loader.shard_loader import make_train_loader
from sray.data_tools.loader.views import read_scene_views
from sray.data_tools.png import decode_png, png16_to_depth
from sray.data_tools.readers.convert import ConvertConfig, convert_scene
from sray.data_tools.scene import IGNORE_ID
from sray.data_tools.shards.manifest import read_manifest
from sray.data_tools.shards.writer import write_shards
from sray.jobs.cli import main

SCALE, H, W, N_SOURCE = 2.0, 32, 40, 3
KINDS = ("nerfstudio", "colmap-text", "colmap-binary")


@pytest.fixture(scope="module")
def imports(tmp_path_factory) -> dict[str, Path]:
    """Shard folders of the three imports of one 8-view room (scene ``cap``), by kind."""
    root = tmp_path_factory.mktemp("captures")
    room = make_scene("room", n_views=8, height=H, width=W, seed=2)
    out = {}
    for kind in KINDS:
        src = root / kind / "src"
        if kind == "nerfstudio":
            write_nerfstudio(room, src, SCALE, ply=True)
        else:
            write_colmap(room, src, SCALE, binary=kind == "colmap-binary")
        convert_scene(ConvertConfig(format=kind.split("-")[0], src=src, out=root / kind / "scenes", name="cap",
                                    size_hw=(H, W), holdout_every=0, options={"scale": SCALE}))
        write_shards(root / kind / "scenes", root / kind / "shards", neighbours=4, progress=False)
        out[kind] = root / kind / "shards"
    return out


def arrays(shards: Path) -> tuple[np.ndarray, np.ndarray, np.ndarray, tuple[float, float]]:
    """Images, poses, intrinsics and (near, far) of scene ``cap`` of a shard folder, in view order."""
    entry = read_manifest(shards).scenes["cap"]
    views = read_scene_views(shards, entry)
    ids = entry.meta["view_ids"]
    return (np.stack([views[v].rgb() for v in ids]), np.stack([views[v].c2w for v in ids]),
            np.stack([views[v].K for v in ids]), (entry.meta["near"], entry.meta["far"]))


def test_the_three_imports_label_alike_and_no_frame_is_its_own_source(imports, tiny_checkpoint, one_thread):
    model = sray.load(tiny_checkpoint, n_source=N_SOURCE, device="cpu")
    _, _, _, bounds = arrays(imports["colmap-text"])
    results = {}
    for kind in KINDS:
        images, poses, Ks, _ = arrays(imports[kind])
        results[kind] = model.label(images, poses, Ks, depth_range=bounds)
    reference = results["colmap-text"]
    assert reference.label.shape == (8, H, W) and reference.label.dtype == np.uint8
    assert len(np.unique(reference.label)) > 1  # a constant map would make the comparison empty
    for kind in KINDS:
        np.testing.assert_array_equal(results[kind].label, reference.label, err_msg=kind)
        np.testing.assert_allclose(results[kind].depth, reference.depth, atol=1e-4, err_msg=kind)
        assert results[kind].sources == reference.sources
    for i, ids in enumerate(reference.sources):
        assert i not in ids and len(set(ids)) == N_SOURCE


def test_the_api_refuses_bad_conventions_naming_the_argument(imports, tiny_checkpoint):
    model = sray.load(tiny_checkpoint, n_source=N_SOURCE, device="cpu")
    images, poses, Ks, bounds = arrays(imports["colmap-binary"])
    flipped = poses.copy()
    flipped[2, :3, 1] *= -1
    with pytest.raises(ValueError, match=r"poses\[2\]: c2w rotation has determinant"):
        model.label(images, flipped, Ks, bounds)
    with pytest.raises(ValueError, match="images must be a uint8 array"):
        model.label(images.astype(np.float32), poses, Ks, bounds)
    with pytest.raises(ValueError, match="depth_range must be"):
        model.label(images, poses, Ks[0], (2.0, 1.0))


@pytest.fixture(scope="module")
def command_run(imports, tiny_checkpoint, tmp_path_factory, one_thread) -> Path:
    """``sray label`` (no tracking) on the COLMAP binary import, 2 fly-through frames; its output folder."""
    out = tmp_path_factory.mktemp("labels")
    code = main(["label", "--checkpoint", str(tiny_checkpoint), "--data", str(imports["colmap-binary"]), "--out",
                 str(out), "--n-source", str(N_SOURCE), "--flythrough-frames", "2", "--no-track"])
    assert code == 0
    return out / "cap"


def test_the_command_writes_the_api_outputs(command_run, imports, tiny_checkpoint):
    images, poses, Ks, bounds = arrays(imports["colmap-binary"])
    expected = sray.load(tiny_checkpoint, n_source=N_SOURCE, device="cpu").label(images, poses, Ks, bounds)
    record = json.loads((command_run / "labels.json").read_text())
    ids = [f["view_id"] for f in record["frames"]]
    assert record["labelled"] is False and "scores" not in record and (record["near"], record["far"]) == bounds
    for i, view in enumerate(ids):
        png = {sub: decode_png((command_run / sub / f"{view}.png").read_bytes(), sub)
               for sub in ("label", "overlay", "confidence", "depth")}
        np.testing.assert_array_equal(png["label"], expected.label[i])
        np.testing.assert_allclose(png["confidence"] / 65535.0, expected.confidence[i], atol=1e-5)
        np.testing.assert_allclose(png16_to_depth(png["depth"]), expected.depth[i], atol=1e-3)
        assert png["overlay"].shape == (H, W, 3)
        assert record["frames"][i]["source_ids"] == [ids[j] for j in expected.sources[i]]
    assert sorted(p.name for p in (command_run / "flythrough").iterdir()) == [
        "flythrough.gif", "flythrough.mp4", "flythrough.webm", "frames.json", "protocol.txt"]


def test_a_labelled_scene_is_scored_against_the_labels_it_did_not_use(tiny_shards, tiny_checkpoint, tmp_path,
                                                                       one_thread, mlflow_template):
    scene = "synth_test_000"
    shutil.copyfile(mlflow_template, tmp_path / "mlflow.db")
    uri = f"sqlite:///{tmp_path / 'mlflow.db'}"
    code = main(["label", "--checkpoint", str(tiny_checkpoint), "--data", str(tiny_shards), "--out", str(tmp_path),
                 "--scenes", scene, "--n-source", str(N_SOURCE), "--flythrough-frames", "0", "--tracking-uri", uri])
    assert code == 0 and not (tmp_path / scene / "flythrough").exists()
    record = json.loads((tmp_path / scene / "labels.json").read_text())
    views = read_scene_views(tiny_shards, read_manifest(tiny_shards).scenes[scene])
    n = len(record["class_names"])
    conf = np.zeros((n, n), np.int64)
    for frame in record["frames"]:  # a plain loop over the written maps
        pred = decode_png((tmp_path / scene / "label" / f"{frame['view_id']}.png").read_bytes(), "label")
        truth = views[frame["view_id"]].label()
        for t, p in zip(truth.ravel(), pred.ravel()):
            if t != IGNORE_ID:
                conf[t, p] += 1
        assert frame["view_id"] not in frame["source_ids"]
    present = conf.sum(1) > 0
    iou = np.diag(conf)[present] / (conf.sum(1) + conf.sum(0) - np.diag(conf))[present]
    assert record["scores"]["miou"] == pytest.approx(iou.mean(), abs=1e-9)
    client = MlflowClient(uri)  # one tracked run holds the scores and the files
    (run,) = client.search_runs([client.get_experiment_by_name("sray-label").experiment_id])
    assert run.info.status == "FINISHED" and run.data.tags["sray.kind"] == "label"
    assert run.data.metrics[f"{scene}/miou"] == pytest.approx(iou.mean(), abs=1e-9)
    assert [Path(f.path).name for f in client.list_artifacts(run.info.run_id, scene)] == ["labels.json"]


def test_unlabelled_captures_pass_check_and_shard_and_training_refuses_them(imports):
    shards = imports["colmap-text"]
    assert check_dataset(shards.parent / "scenes") == []
    assert read_manifest(shards).scenes["cap"].meta["labelled"] is False
    with pytest.raises(ValueError, match=r"scenes \['cap'\] have no labels .*label them with `sray label`"):
        make_train_loader(shards, n_source=2, top_k=3, rays_per_batch=8, batches_per_epoch=1, rank=0, world_size=1,
                          num_workers=0, seed=0)
