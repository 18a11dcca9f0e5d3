"""Capture readers (nerfstudio, COLMAP text and binary): a procedural scene written out in each format imports
back to the same cameras (1e-5) and pixels; a planted convention error (flipped axis, transposed rotation, half-pixel
principal point) fails; distortion terms round-trip through OpenCV's forward models; scale and depth bounds come
from the capture's points and depth (within 5%), and without either the conversion stops naming both ways."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pytest
from capture_writers import write_colmap, write_nerfstudio
from scene_fixtures import make_scene

from sray.data_tools.check.scenes import check_dataset
from sray.data_tools.png import encode_png
from sray.data_tools.readers.camera_models import colmap_camera, nerfstudio_camera, undistort_maps
from sray.data_tools.readers.convert import ConvertConfig, convert_scene
from sray.data_tools.scene import IGNORE_ID, Scene
from sray.data_tools.scene_folder import read_scene
from sray.jobs.cli import main

SCALE = 2.5
"""Metres per capture unit of the written captures."""
H, W = 30, 40


@pytest.fixture(scope="module")
def original() -> Scene:
    """The procedural room the captures are written from (8 views of 40x30)."""
    return make_scene("room", n_views=8, height=H, width=W, seed=5)


def write_capture(kind: str, scene: Scene, dst: Path, **kw) -> Path:
    """``scene`` as capture ``kind`` (nerfstudio, colmap-text, colmap-binary) under ``dst``."""
    if kind == "nerfstudio":
        return write_nerfstudio(scene, dst, SCALE, ply=True, **kw)
    return write_colmap(scene, dst, SCALE, binary=kind == "colmap-binary", **kw)


def convert(kind: str, src: Path, out: Path, **options) -> Scene:
    """Convert a written capture at its own size with every view kept; returns the scene read back."""
    cfg = ConvertConfig(format=kind.split("-")[0], src=src, out=out, name="cap", size_hw=(H, W), holdout_every=0,
                        options=options)
    return read_scene(convert_scene(cfg).scene_dir)


def camera_errors(a: Scene, b: Scene) -> tuple[float, float]:
    """Largest |K difference| (pixels) and |c2w difference| over the views of two scenes, in order."""
    dk = dc = 0.0
    for va, vb in zip(a.views(), b.views(), strict=True):
        dk = max(dk, float(np.abs(va.K - vb.K).max()))
        dc = max(dc, float(np.abs(va.c2w - vb.c2w).max()))
    return dk, dc


@pytest.mark.parametrize("kind", ["nerfstudio", "colmap-text", "colmap-binary"])
def test_a_written_capture_imports_back_to_the_original_cameras_and_pixels(kind, original, tmp_path):
    src = write_capture(kind, original, tmp_path / "src")
    scene = convert(kind, src, tmp_path / "ds", scale=SCALE)
    dk, dc = camera_errors(scene, original)
    assert dk < 1e-5 and dc < 1e-5, (dk, dc)
    for got, want in zip(scene.views(), original.views()):
        np.testing.assert_array_equal(got.rgb, want.rgb)
        assert (got.label == IGNORE_ID).all() and not got.depth.any()
    assert scene.meta.labelled is False and scene.meta.extra["scale_m_per_unit"] == SCALE
    assert check_dataset(tmp_path / "ds") == []
    # bounds from the points each view sees, against the depth-measured bounds of the original
    assert scene.meta.near == pytest.approx(original.meta.near, rel=0.15)
    assert scene.meta.far == pytest.approx(original.meta.far, rel=0.15)


@pytest.mark.parametrize("kind, mistake", [("nerfstudio", "opencv-axes"), ("colmap-text", "transposed"),
                                           ("colmap-binary", "pixel-centre"), ("nerfstudio", "pixel-centre")])
def test_a_planted_convention_error_is_caught(kind, mistake, original, tmp_path):
    src = write_capture(kind, original, tmp_path / "src", mistake=mistake)
    try:
        scene = convert(kind, src, tmp_path / "ds", scale=SCALE)
    except ValueError as e:  # the import itself may refuse it (a pose flipped to a reflection)
        assert "determinant -1" in str(e) or "fails `sray data check`" in str(e), e
        return
    dk, dc = camera_errors(scene, original)
    assert (dk > 0.4) if mistake == "pixel-centre" else (dc > 0.1), (dk, dc)


def test_a_flipped_axis_is_refused(original, tmp_path):
    src = write_nerfstudio(original, tmp_path / "src", SCALE)
    data = json.loads((src / "transforms.json").read_text())
    m = np.array(data["frames"][3]["transform_matrix"])
    m[:3, 1] *= -1  # y axis flipped: a reflection
    data["frames"][3]["transform_matrix"] = m.tolist()
    (src / "transforms.json").write_text(json.dumps(data))
    with pytest.raises(ValueError, match="frame_00003.png: the pose's rotation has determinant -1"):
        convert("nerfstudio", src, tmp_path / "ds", scale=SCALE)
    assert not (tmp_path / "ds" / "cap").exists()


def forward_pixels(camera, pixels: np.ndarray) -> np.ndarray:
    """Where the lens of ``camera`` images the rays of undistorted pixels (n, 2): OpenCV's forward projection
    (``cv2.projectPoints`` / ``cv2.fisheye.projectPoints``) of each pixel's ray, independent of the undistort maps."""
    rays = np.concatenate([(pixels - camera.K[:2, 2]) / np.diag(camera.K)[:2], np.ones((len(pixels), 1))], axis=1)
    if camera.fisheye:
        out, _ = cv2.fisheye.projectPoints(rays[:, None, :], np.zeros(3), np.zeros(3), camera.K, camera.dist)
    else:
        out, _ = cv2.projectPoints(rays, np.zeros(3), np.zeros(3), camera.K, camera.dist)
    return out.reshape(-1, 2)


@pytest.mark.parametrize("source", ["colmap OPENCV", "colmap RADIAL", "colmap OPENCV_FISHEYE", "nerfstudio OPENCV",
                                    "nerfstudio OPENCV_FISHEYE"])
def test_distortion_terms_round_trip_through_opencv(source):
    fx, fy, cx, cy = 300.0, 310.0, 160.5, 120.5
    k1, k2, k3, k4, p1, p2 = -0.12, 0.03, 0.004, -0.001, 0.0015, -0.0008
    fmt, model = source.split()
    if fmt == "colmap":
        params = {"OPENCV": [fx, fy, cx, cy, k1, k2, p1, p2], "RADIAL": [fx, cx, cy, k1, k2],
                  "OPENCV_FISHEYE": [fx, fy, cx, cy, k1, k2, k3, k4]}[model]
        camera = colmap_camera(model, np.array(params), (240, 320), "cam 1")
        expected = {"OPENCV": [k1, k2, p1, p2], "RADIAL": [k1, k2, 0, 0], "OPENCV_FISHEYE": [k1, k2, k3, k4]}[model]
    else:
        fields = {"camera_model": model, "fl_x": fx, "fl_y": fy, "cx": cx, "cy": cy, "w": 320, "h": 240, "k1": k1,
                  "k2": k2, "k3": k3}
        fields.update({"k4": k4} if model == "OPENCV_FISHEYE" else {"p1": p1, "p2": p2})
        camera = nerfstudio_camera(fields, "frame 0")
        expected = [k1, k2, k3, k4] if model == "OPENCV_FISHEYE" else [k1, k2, p1, p2, k3]
    np.testing.assert_allclose(camera.dist, expected)
    assert camera.K[0, 2] == cx - 0.5 and camera.K[1, 2] == cy - 0.5  # capture pixel centres at +0.5
    map_x, map_y = undistort_maps(camera)
    v, u = np.mgrid[20:220:25, 30:300:30]
    pixels = np.stack([u.ravel(), v.ravel()], axis=1).astype(np.float64)
    lens = forward_pixels(camera, pixels)
    mapped = np.stack([map_x[v.ravel(), u.ravel()], map_y[v.ravel(), u.ravel()]], axis=1)
    np.testing.assert_allclose(mapped, lens, atol=2e-3)
    assert np.abs(lens - pixels).max() > 1.0  # the distortion is not negligible: the test would see a wrong order


def test_a_capture_through_a_distorting_lens_imports_as_the_pinhole_images(tmp_path):
    room = make_scene("room", n_views=4, height=60, width=80, seed=1)
    lens = (-0.25, 0.08, 0.004, -0.003, 0.0)
    src = write_nerfstudio(room, tmp_path / "src", 1.0, ply=True, distortion=lens)
    cfg = ConvertConfig(format="nerfstudio", src=src, out=tmp_path / "ds", name="cap", size_hw=(60, 80),
                        holdout_every=0, options={"scale": 1.0})
    scene = read_scene(convert_scene(cfg).scene_dir)
    inner = (slice(8, 52), slice(10, 70))  # away from the borders the lens never saw

    def blur(rgb: np.ndarray) -> np.ndarray:  # two bilinear resamplings soften the checker edges: compare shapes
        return cv2.GaussianBlur(rgb.astype(np.float32), (0, 0), 1.5)[inner]

    for got, want, frame in zip(scene.views(), room.views(), sorted((src / "images").iterdir())):
        recorded = cv2.cvtColor(cv2.imread(str(frame)), cv2.COLOR_BGR2RGB)
        error = np.abs(blur(got.rgb) - blur(want.rgb)).mean()
        ignored = np.abs(blur(recorded) - blur(want.rgb)).mean()  # the lens left in: grey levels off by ~3
        assert error < 1.0 and ignored > 3 * error, (error, ignored)


def test_models_opencv_cannot_invert_are_refused_naming_the_camera():
    with pytest.raises(ValueError, match="camera 3 \\(FOV\\): camera model FOV cannot be undistorted with OpenCV"):
        colmap_camera("FOV", np.array([300.0, 300.0, 160.0, 120.0, 0.9]), (240, 320), "camera 3 (FOV)")
    with pytest.raises(ValueError, match="frames\\[2\\].*EQUIRECTANGULAR cannot be undistorted"):
        nerfstudio_camera({"camera_model": "EQUIRECTANGULAR", "fl_x": 1, "cx": 1, "cy": 1, "w": 2, "h": 2},
                          "frames[2]")


@pytest.mark.parametrize("point_noise", [0.0, 0.05])
def test_scale_is_measured_from_depth_maps_against_the_points(point_noise, original, tmp_path):
    src = write_nerfstudio(original, tmp_path / "src", SCALE, depth=True, ply=True, point_noise=point_noise)
    scene = convert("nerfstudio", src, tmp_path / "ds")
    measured = scene.meta.extra["scale_m_per_unit"]
    assert measured == pytest.approx(SCALE, rel=0.05)
    for got, want in zip(scene.views(), original.views()):
        np.testing.assert_allclose(got.c2w[:3, 3], want.c2w[:3, 3] * measured / SCALE, atol=1e-9)
        np.testing.assert_allclose(got.depth, want.depth, atol=1e-3)  # metric depth kept (RGB-D), mm PNG
    assert (scene.meta.near, scene.meta.far) == pytest.approx((original.meta.near, original.meta.far), rel=0.02)


@pytest.mark.parametrize("kind", ["colmap-text", "nerfstudio"])
def test_without_scale_or_metric_depth_the_conversion_stops_naming_both(kind, original, tmp_path):
    src = write_capture(kind, original, tmp_path / "src")
    with pytest.raises(ValueError, match="pass --scale METRES_PER_UNIT, or give metric depth maps") as error:
        convert(kind, src, tmp_path / "ds")
    assert "\n" not in str(error.value) and not (tmp_path / "ds" / "cap").exists()


def test_the_cli_converts_a_capture_and_check_counts_it_as_unlabelled(original, tmp_path, capsys):
    src = write_colmap(original, tmp_path / "src", SCALE, binary=True)
    base = ["data", "convert", str(src), "--format", "colmap", "--out", str(tmp_path / "ds"), "--size", f"{W}x{H}",
            "--holdout-every", "0", "--name", "cap"]
    assert main(base) == 1
    assert "pass --scale METRES_PER_UNIT" in capsys.readouterr().err
    assert main([*base, "--scale", str(SCALE)]) == 0
    assert "wrote " in capsys.readouterr().out
    assert main(["data", "check", str(tmp_path / "ds")]) == 0
    assert "1 scene (1 without labels: inference only" in capsys.readouterr().out
    label = tmp_path / "ds" / "cap" / "label" / "000003.png"
    label.write_bytes(encode_png(np.full((H, W), 3, np.uint16)))  # a class id in a scene that says it has none
    assert main(["data", "check", str(tmp_path / "ds")]) == 1
    assert "scene.json says 'labelled': false, but this label image holds ids" in capsys.readouterr().out
