"""``sray render`` on a tiny checkpoint and tiny shards: a frame at a source pose equals evaluation's render, the
videos read back with the asked frames and size and match the panels, frames.json and the tracked run hold what
was rendered, no test view is decoded, a failed render leaves no video, and bad input is refused in one line."""

from __future__ import annotations

import dataclasses
import json
import shutil
from pathlib import Path

import cv2
import numpy as np
import pytest
import torch
from fleet_fixtures import one_thread, tiny_checkpoint  # noqa: F401  (pytest fixtures, used by name)
from mlflow_fixtures import mlflow_template  # noqa: F401
from PIL import Image
from train_fixtures import tiny_shards  # noqa: F401

from sray.data_tools.loader.sample_types import QueryCamera, SceneQuery
from sray.data_tools.loader.samples import eval_sample
from sray.data_tools.loader.views import StoredView
from sray.data_tools.scene import source_pool
from sray.model.fast_render import FastRender
from sray.platform.common.eval_protocol import EvalProtocol
from sray.platform.eval.view_scoring import predict_view, sray_renderer
from sray.platform.finetune.render_model import render_model
from sray.platform.finetune.scene_artifacts import adapted_state, checkpoint_sha256, save_sray_delta
from sray.platform.render.camera_paths import CameraPath, spline_path
from sray.platform.render.flythrough import Flythrough
from sray.platform.render.frames import render_frame
from sray.platform.render.panels import panel_layout
from sray.platform.render.plan import plan_flythrough
from sray.platform.viz.palette import colorize

SCENE = "synth_test_000"
"""The tiny shards' unseen test scene (8 source, 8 finetune, 4 test views of 32x40)."""
N_FRAMES = 3
CPU = torch.device("cpu")


def psnr(a: np.ndarray, b: np.ndarray) -> float:
    """PSNR in dB of two uint8 images."""
    mse = np.mean((a.astype(np.float64) - b.astype(np.float64)) ** 2)
    return float("inf") if mse == 0 else 10 * np.log10(255.0**2 / mse)


def read_video(path: Path) -> list[np.ndarray]:
    """Every frame of a video as uint8 RGB (H, W, 3), decoded by OpenCV."""
    capture, frames = cv2.VideoCapture(str(path)), []
    while True:
        ok, frame = capture.read()
        if not ok:
            break
        frames.append(frame[..., ::-1])
    capture.release()
    return frames


@pytest.mark.parametrize("fast", [FastRender(), None], ids=["fast", "full"])
def test_a_frame_at_a_source_pose_equals_the_eval_render(tiny_shards, tiny_checkpoint, one_thread, fast):
    plan = plan_flythrough(tiny_shards, SCENE, n_frames=1)
    query = plan.meta.splits["source"][2]
    view = plan.views[query]
    hw = view.rgb().shape[:2]
    plan = dataclasses.replace(plan, path=CameraPath(c2w=view.c2w[None], K=view.K[None], hw=hw, describe="a source"))
    net, _ = render_model(tiny_checkpoint, None, SCENE)
    fly = Flythrough(net, plan, 3, fast)
    ids = fly.picker.choose(view.K, view.c2w, hw)
    assert ids[0] == query and set(ids) <= set(plan.meta.splits["source"])  # a view sees all of itself

    sample = eval_sample(plan.views, query, ids, SCENE, plan.meta.near, plan.meta.far)
    expected = predict_view(sray_renderer(net, sample, CPU, fast), sample, 1, fly.runtime.chunk, CPU, fast)
    camera = SceneQuery(scene=SCENE, query_id="frame 0", sources=fly.picker.sources(ids),
                        query=QueryCamera(K=sample.query.K, c2w=sample.query.c2w), near=sample.near, far=sample.far)
    src = camera.sources
    frame = render_frame(net.ray_renderer(net.encode(src.rgb, src.K, src.c2w, src.depth), fast), camera, hw,
                         fly.runtime.chunk, CPU, fast)
    torch.testing.assert_close(frame.label, expected.pred_label, rtol=0, atol=0)
    torch.testing.assert_close(frame.rgb, expected.pred_rgb, rtol=0, atol=1e-6)
    assert ((frame.confidence >= 1 / net.cfg.n_classes - 1e-6) & (frame.confidence <= 1 + 1e-6)).all()
    assert ((frame.depth >= plan.meta.near - 1e-4) & (frame.depth <= plan.meta.far + 1e-4)).all()

    picture, picture_ids = fly.picture(0, CPU)  # the panel picture shows the same labels and colours
    assert picture_ids == ids
    layout = panel_layout(hw, net.cfg.n_classes)
    tiles = {name: picture[y:y + h:layout.scale, x:x + w:layout.scale] for name, (x, y, w, h) in layout.tiles.items()}
    np.testing.assert_array_equal(tiles["semantics"], colorize(expected.pred_label.numpy(), net.cfg.n_classes))
    rgb = (expected.pred_rgb.numpy() * 255 + 0.5).astype(np.uint8)
    assert np.abs(tiles["rgb"].astype(int) - rgb).max() <= 1


@pytest.fixture(scope="module")
def rendered(tiny_shards, tiny_checkpoint, mlflow_template, tmp_path_factory, one_thread):
    """One tracked ``sray render`` of a 3-frame spline (view ids decoded meanwhile recorded); returns
    (out folder, tracking URI, decoded view ids, printed output)."""
    from sray.jobs.cli import main

    folder = tmp_path_factory.mktemp("render")
    db = folder / "mlflow.db"
    shutil.copyfile(mlflow_template, db)
    decoded: set[str] = set()
    with pytest.MonkeyPatch.context() as patch:
        for name in ("rgb", "depth", "label"):
            original = getattr(StoredView, name)

            def recording(self, _original=original):
                decoded.add(self.view_id)
                return _original(self)

            patch.setattr(StoredView, name, recording)
        code = main(["render", "--checkpoint", str(tiny_checkpoint), "--data", str(tiny_shards), "--scene", SCENE,
                     "--out", str(folder / "out"), "--frames", str(N_FRAMES), "--n-source", "3",
                     "--tracking-uri", f"sqlite:///{db}"])
    assert code == 0
    return folder / "out", f"sqlite:///{db}", decoded


def test_videos_have_the_asked_frames_and_size_and_match_the_panels(rendered, tiny_shards, tiny_checkpoint):
    out, _, _ = rendered
    plan = plan_flythrough(tiny_shards, SCENE, n_frames=N_FRAMES)
    net, _ = render_model(tiny_checkpoint, None, SCENE)
    fly = Flythrough(net, plan, 3, FastRender())
    first, _ = fly.picture(0, CPU, "zero-shot")
    assert first.shape == (*fly.layout.size, 3)
    for suffix in ("webm", "mp4"):
        frames = read_video(out / f"flythrough.{suffix}")
        assert len(frames) == N_FRAMES and frames[0].shape == first.shape, suffix
        assert psnr(frames[0], first) >= 30.0, suffix
    with Image.open(out / "flythrough.gif") as gif:
        assert gif.n_frames == N_FRAMES and gif.width <= 480
    assert sorted(p.name for p in out.iterdir()) == ["flythrough.gif", "flythrough.mp4", "flythrough.webm",
                                                     "frames.json", "protocol.txt"]


def test_frames_json_records_poses_sources_and_the_protocol(rendered, tiny_shards, tiny_checkpoint):
    out, _, decoded = rendered
    record = json.loads((out / "frames.json").read_text())
    plan = plan_flythrough(tiny_shards, SCENE, n_frames=N_FRAMES)
    pool = source_pool(plan.meta)
    expected = spline_path(np.stack([plan.views[v].c2w for v in pool]), N_FRAMES)
    assert record["n_frames"] == N_FRAMES and len(record["frames"]) == N_FRAMES
    np.testing.assert_allclose([f["c2w"] for f in record["frames"]], expected, atol=1e-12)
    np.testing.assert_allclose(record["frames"][0]["c2w"], plan.views[pool[0]].c2w, atol=0)  # starts on a camera
    assert all(len(f["source_ids"]) == 3 and set(f["source_ids"]) <= set(plan.meta.splits["source"])
               for f in record["frames"])
    assert record["model"] == {"checkpoint": str(Path(tiny_checkpoint).resolve())}
    protocol = EvalProtocol.from_manifest(plan.manifest, 3, 1, str(tiny_shards / "manifest.json"), "rgb",
                                          "").rendered_by(FastRender())
    assert record["protocol"] == protocol.to_json() and record["protocol_line"] == protocol.describe()
    assert (out / "protocol.txt").read_text() == protocol.describe() + "\n"
    assert decoded and not decoded & set(plan.meta.splits["test"])  # no test view's pixels, depth or labels


def test_the_run_holds_the_videos_as_artifacts(rendered):
    from mlflow import MlflowClient

    _, uri, _ = rendered
    client = MlflowClient(uri)
    (run,) = client.search_runs([client.get_experiment_by_name("sray-render").experiment_id])
    assert run.info.status == "FINISHED" and run.data.tags["sray.kind"] == "render"
    assert run.data.tags["sray.scene"] == SCENE and "frustum-overlap" in run.data.tags["sray.protocol"]
    logged = {Path(f.path).name for f in client.list_artifacts(run.info.run_id, "flythrough")}
    assert logged == {"flythrough.webm", "flythrough.mp4", "flythrough.gif", "frames.json", "protocol.txt"}
    assert run.data.metrics["render/n_frames"] == N_FRAMES


@pytest.mark.parametrize("error", [RuntimeError, KeyboardInterrupt])
def test_a_failed_render_leaves_no_video(tiny_shards, tiny_checkpoint, one_thread, tmp_path, monkeypatch, error):
    import sray.platform.render.flythrough as flythrough

    calls = []

    def failing(*args, **kwargs):
        calls.append(1)
        if len(calls) == 2:
            raise error("stopped mid-render")
        return render_frame(*args, **kwargs)

    monkeypatch.setattr(flythrough, "render_frame", failing)
    fly = Flythrough(render_model(tiny_checkpoint, None, SCENE)[0],
                     plan_flythrough(tiny_shards, SCENE, n_frames=3, size_hw=(16, 20)), 3, FastRender())
    with pytest.raises(error):
        fly.render(tmp_path / "out", CPU, progress=False)
    assert list((tmp_path / "out").iterdir()) == []  # no video, no frames.json, no staging folder


def _artifact(folder: Path, checkpoint: Path, scene: str, base_sha256: str | None = None) -> tuple[Path, str]:
    """A scene delta of one adapted tensor (set to 0.5) of the tiny checkpoint's model: (its file, the tensor's key)."""
    net, _ = render_model(checkpoint, None, SCENE)
    key = next(k for k in net.state_dict() if not k.startswith("encoder.") and k.endswith("weight"))
    tensors = {k: torch.full_like(v, 0.5) for k, v in adapted_state(net, [key]).items()}
    path = folder / scene / "sray_delta.safetensors"
    path.parent.mkdir(parents=True, exist_ok=True)
    save_sray_delta(path, tensors, base_sha256 or checkpoint_sha256(checkpoint), [key], scene)
    return path, key


def test_an_artifact_is_applied_as_the_fleet_applies_it(tiny_checkpoint, tmp_path):
    path, key = _artifact(tmp_path, tiny_checkpoint, SCENE)
    net, about = render_model(tiny_checkpoint, path.parent, SCENE)  # a fleet's scenes/<scene>/sray folder
    assert about == {"checkpoint": str(Path(tiny_checkpoint).resolve()), "artifact": str(path.resolve())}
    assert (net.state_dict()[key] == 0.5).all()


def _camera_path_file(folder: Path, frame: dict) -> Path:
    """A camera_path.json with one frame."""
    path = folder / "camera_path.json"
    path.write_text(json.dumps({"render_height": 16, "render_width": 20, "camera_path": [frame]}))
    return path


GL_POSE = [1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 2, 0, 0, 0, 1]
"""Row-major OpenGL camera-to-world of a camera 2 m up the world z axis."""


@pytest.mark.parametrize("case", ["unknown scene", "another checkpoint's artifact", "another scene's artifact",
                                  "missing field", "non-rigid pose", "too many sources"])
def test_bad_input_is_refused_in_one_line_and_nothing_is_written(tiny_shards, tiny_checkpoint, tmp_path, monkeypatch,
                                                                 capsys, case):
    from sray.jobs.cli import main

    inputs = tmp_path / "inputs"
    inputs.mkdir()
    scene, extra, expect = SCENE, [], []
    if case == "unknown scene":
        scene, expect = "no_such_scene", ["manifest.json", "'scenes'", "no_such_scene"]
    elif case == "another checkpoint's artifact":
        path, _ = _artifact(inputs, tiny_checkpoint, SCENE, base_sha256="0" * 64)
        extra, expect = ["--artifact", str(path)], [str(path), "base checksum mismatch"]
    elif case == "another scene's artifact":
        path, _ = _artifact(inputs, tiny_checkpoint, "synth_train_000")
        extra, expect = ["--artifact", str(path)], [str(path), "field 'scene'", "synth_train_000"]
    elif case == "missing field":
        path = _camera_path_file(inputs, {"camera_to_world": GL_POSE})
        extra, expect = ["--camera-path", str(path)], [str(path), "'camera_path[0].fov'"]
    elif case == "non-rigid pose":
        path = _camera_path_file(inputs, {"camera_to_world": [2, *GL_POSE[1:]], "fov": 50})
        extra, expect = ["--camera-path", str(path)], [str(path), "'camera_path[0].camera_to_world'", "rigid"]
    else:
        extra, expect = ["--n-source", "9"], [SCENE, "n_source is 9"]
    monkeypatch.chdir(tmp_path)
    code = main(["render", "--checkpoint", str(tiny_checkpoint), "--data", str(tiny_shards), "--scene", scene,
                 "--out", str(tmp_path / "out"), *extra])
    err = capsys.readouterr().err.strip()
    assert code == 2 and err.startswith("sray render: ") and "\n" not in err, err
    assert all(e in err for e in expect), err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["inputs"]  # no output folder, no tracking store
