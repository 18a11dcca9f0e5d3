"""``sray data check``: every defect is caught and names the exact bad file; the check writes nothing."""

from __future__ import annotations

import argparse
import json
import shutil
import tempfile
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from sray.data_tools.check.rules import REQUIRED_FIELDS
from sray.data_tools.check.scenes import CheckLimits, check_dataset, check_scene_object
from sray.data_tools.label_spaces import SCANNET20
from sray.data_tools.png import encode_png
from sray.data_tools.scene import IGNORE_ID, Scene, SceneMeta, View
from sray.data_tools.scene_folder import write_dataset_index, write_scene
from sray.jobs.data import command as data_command

H, W = 16, 20


def small_scene(name: str, n_views: int, role: str, splits: dict[str, list[int]], seed: int) -> Scene:
    """A valid scene: centred K, rigid poses, depth in metres, ScanNet-20 labels with ignore."""
    rng = np.random.default_rng(seed)
    views = []
    for i in range(n_views):
        c2w = np.eye(4)
        c, s = np.cos(0.1 * i), np.sin(0.1 * i)
        c2w[:3, :3] = np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])  # turn about the y axis
        c2w[:3, 3] = [0.1 * i, 0.0, 0.0]
        label = rng.integers(0, 20, (H, W)).astype(np.uint16)
        label[0, 0] = IGNORE_ID
        K = np.array([[18.0, 0, (W - 1) / 2], [0, 18.0, (H - 1) / 2], [0, 0, 1]])
        views.append(View(f"{i:04d}", rng.integers(0, 256, (H, W, 3), dtype=np.uint8),
                          rng.uniform(0.5, 4.0, (H, W)).astype(np.float32), label, K, c2w))
    ids = [v.view_id for v in views]
    meta = SceneMeta(name, "scannet20", list(SCANNET20), ids, {k: [ids[i] for i in v] for k, v in splits.items()},
                     near=0.4, far=4.5, role=role)
    return Scene.in_memory(meta, views)


@pytest.fixture(scope="module")
def template(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A valid two-scene dataset: a train scene and a test scene."""
    root = tmp_path_factory.mktemp("valid")
    write_scene(small_scene("alpha", 6, "train", {"train": [0, 1, 2, 4, 5], "test": [3]}, 0), root)
    write_scene(small_scene("beta", 5, "test", {"source": [0, 2], "finetune": [4], "test": [1, 3]}, 1), root)
    write_dataset_index(root, ["alpha", "beta"])
    return root


@pytest.fixture
def dataset(template: Path, tmp_path: Path) -> Path:
    """A fresh copy of the valid dataset for one test to damage."""
    return Path(shutil.copytree(template, tmp_path / "ds"))


def edit_json(path: Path, change: Callable[[dict], None]) -> None:
    """Apply ``change`` to the JSON object stored in ``path``."""
    data = json.loads(path.read_text())
    change(data)
    path.write_text(json.dumps(data))


def edit_camera(key: str, change: Callable[[np.ndarray], np.ndarray]) -> Callable[[Path], Path]:
    """A defect that rewrites K or c2w of view 0002 of scene alpha."""
    def apply(root: Path) -> Path:
        path = root / "alpha" / "cameras.json"
        def cam(d: dict) -> None:
            d["0002"][key] = change(np.array(d["0002"][key], dtype=float)).tolist()
        edit_json(path, cam)
        return path
    return apply


def edit_meta(scene: str, change: Callable[[dict], None]) -> Callable[[Path], Path]:
    """A defect that edits scene.json of ``scene``."""
    def apply(root: Path) -> Path:
        edit_json(root / scene / "scene.json", change)
        return root / scene / "scene.json"
    return apply


def replace_png(sub: str, image: np.ndarray | bytes | None) -> Callable[[Path], Path]:
    """A defect that replaces (or deletes, for None) ``alpha/<sub>/0001.png``."""
    def apply(root: Path) -> Path:
        path = root / "alpha" / sub / "0001.png"
        if image is None:
            path.unlink()
        else:
            path.write_bytes(image if isinstance(image, bytes) else encode_png(image))
        return path
    return apply


def _set(d: dict, key: str, value: object) -> None:
    d[key] = value


def _nan(m: np.ndarray) -> np.ndarray:
    m[0, 3] = np.nan
    return m


def _scaled(m: np.ndarray) -> np.ndarray:
    m[:3, :3] *= 1.1
    return m


def _mirrored(m: np.ndarray) -> np.ndarray:
    m[:3, 0] *= -1
    return m


def _row(m: np.ndarray, r: int, values: list[float]) -> np.ndarray:
    m[r] = values
    return m


def _entry(m: np.ndarray, r: int, c: int, value: float) -> np.ndarray:
    m[r, c] = value
    return m


def _missing_listed_scene(root: Path) -> Path:
    shutil.rmtree(root / "beta")
    return root / "dataset.json"


def _unlisted_scene(root: Path) -> Path:
    shutil.copytree(root / "beta", root / "gamma")
    edit_json(root / "gamma" / "scene.json", lambda d: _set(d, "name", "gamma"))
    return root / "dataset.json"


def _broken_scene_json(root: Path) -> Path:
    (root / "beta" / "scene.json").write_text("{oops")
    return root / "beta" / "scene.json"


def _no_camera_entry(root: Path) -> Path:
    edit_json(root / "alpha" / "cameras.json", lambda d: d.pop("0004"))
    return root / "alpha" / "cameras.json"


DEFECTS: dict[str, tuple[Callable[[Path], Path], str]] = {
    "pose non-finite": (edit_camera("c2w", _nan), "non-finite"),
    "pose not orthonormal": (edit_camera("c2w", _scaled), "not orthonormal"),
    "pose reflection": (edit_camera("c2w", _mirrored), "determinant"),
    "pose last row": (edit_camera("c2w", lambda m: _row(m, 3, [0, 0, 0.5, 1])), "last row"),
    "K principal point outside": (edit_camera("K", lambda m: _entry(m, 0, 2, W + 3.0)), "outside"),
    "K non-positive focal": (edit_camera("K", lambda m: _entry(m, 1, 1, -18.0)), "positive"),
    "K bottom row": (edit_camera("K", lambda m: _row(m, 2, [0, 0, 2])), "[0, 0, 1]"),
    "K of another resolution": (edit_camera("K", lambda m: _entry(_entry(m, 0, 2, W - 0.5), 1, 2, H - 0.5)),
                                "far from the centre"),
    "camera entry missing": (_no_camera_entry, "no K and c2w for view '0004'"),
    "depth size mismatch": (replace_png("depth", np.ones((H, W + 2), np.uint16)), "depth image is 22x16"),
    "label size mismatch": (replace_png("label", np.ones((H + 1, W), np.uint16)), "label image is 20x17"),
    "label id outside space": (replace_png("label", np.full((H, W), 20, np.uint16)), "label ids [20]"),
    "rgb unreadable": (replace_png("rgb", b"\x89PNG garbage"), "not a readable PNG"),
    "rgb 16-bit": (replace_png("rgb", np.ones((H, W, 3), np.uint16)), "expected 8-bit RGB"),
    "depth missing": (replace_png("depth", None), "missing"),
    "rgb size vs image_size": (replace_png("rgb", np.ones((H, W - 1, 3), np.uint8)), "image_size"),
    "scene.json field missing": (edit_meta("alpha", lambda d: d.pop("class_names")), "'class_names' is missing"),
    "scene.json unreadable": (_broken_scene_json, "not readable JSON"),
    "scene.json name mismatch": (edit_meta("alpha", lambda d: _set(d, "name", "other")), "scene folder"),
    "near/far invalid": (edit_meta("alpha", lambda d: _set(d, "far", 0.1)), "near/far"),
    "view id with a dot": (edit_meta("alpha", lambda d: _set(d, "view_ids", [*d["view_ids"], "a.b"])), "'.'"),
    "split references unknown view": (edit_meta("beta", lambda d: d["splits"]["test"].append("9999")),
                                      "unknown views ['9999']"),
    "unknown split name": (edit_meta("beta", lambda d: _set(d["splits"], "val", [])), "unknown split 'val'"),
    "test scene too few source views": (edit_meta("beta", lambda d: _set(d["splits"], "source", ["0000"])),
                                        "needs >= 2 'source'"),
    "test scene without test views": (edit_meta("beta", lambda d: _set(d["splits"], "test", [])), "needs >= 1 'test'"),
    "train scene too few train views": (edit_meta("alpha", lambda d: _set(d["splits"], "train", ["0000", "0001"])),
                                        "needs >= 4 'train'"),
    "test view leaks into source": (edit_meta("beta", lambda d: d["splits"]["source"].append("0001")), "also source"),
    "ignore id inside class ids": (edit_meta("alpha", lambda d: _set(d, "ignore_id", 3)), "ignore_id"),
    "class names of another space": (edit_meta("alpha", lambda d: _set(d, "class_names", ["a", "b"])),
                                     "does not match"),
    "dataset lists a missing scene": (_missing_listed_scene, "lists scene 'beta'"),
    "dataset misses a scene folder": (_unlisted_scene, "does not list scene folder 'gamma'"),
}


def test_valid_dataset_has_no_problems(template: Path) -> None:
    assert check_dataset(template) == []
    assert check_dataset(template / "beta") == []


@pytest.mark.parametrize("defect", list(DEFECTS))
def test_each_defect_is_reported_with_its_file(dataset: Path, defect: str) -> None:
    inject, words = DEFECTS[defect]
    bad_file = inject(dataset)
    problems = check_dataset(dataset)
    assert problems, f"{defect}: not detected"
    hits = [p for p in problems if p.file == str(bad_file) and words in p.what]
    assert hits, f"{defect}: expected a problem on {bad_file} mentioning {words!r}, got {problems}"
    assert all(p.fix for p in problems)


json_values = st.recursive(st.none() | st.booleans() | st.integers() | st.floats() | st.text(max_size=5),
                           lambda inner: st.lists(inner, max_size=4) | st.dictionaries(st.text(max_size=5), inner,
                                                                                       max_size=4), max_leaves=8)


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(field=st.sampled_from([*REQUIRED_FIELDS, "ignore_id"]), value=json_values,
       cam_key=st.sampled_from(["K", "c2w"]), cam_value=json_values)
def test_arbitrary_json_values_are_reported_not_raised(template: Path, field: str, value: object,
                                                       cam_key: str, cam_value: object) -> None:
    """Whatever scene.json and cameras.json hold, the check returns problems instead of crashing."""
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(shutil.copytree(template / "alpha", Path(tmp) / "alpha"))
        edit_json(root / "scene.json", lambda d: _set(d, field, value))
        edit_json(root / "cameras.json", lambda d: _set(d["0001"], cam_key, cam_value))
        problems = check_dataset(root)
    assert all(isinstance(p.file, str) and p.what and p.fix for p in problems)


def test_limits_are_parameters(template: Path) -> None:
    problems = check_dataset(template, CheckLimits(min_train_views=6))
    assert [(Path(p.file).parent.name, "needs >= 6 'train'" in p.what) for p in problems] == [("alpha", True)]


def tree_snapshot(root: Path) -> dict[str, tuple[str, bytes | None]]:
    """Every path under root (dirs too, hidden included) with its kind and bytes."""
    return {str(p.relative_to(root)): ("dir", None) if p.is_dir() else ("file", p.read_bytes())
            for p in sorted(root.rglob("*"))}


def run_cli(argv: list[str]) -> int:
    """Run ``sray data check ARGV`` through its own parser; returns the exit code."""
    parser = argparse.ArgumentParser()
    data_command.register_check(parser.add_subparsers())
    args = parser.parse_args(["check", *argv])
    return args.func(args)


def test_check_writes_nothing(dataset: Path, capsys: pytest.CaptureFixture) -> None:
    DEFECTS["label id outside space"][0](dataset)
    DEFECTS["pose reflection"][0](dataset)
    before = tree_snapshot(dataset)
    stats = {p: p.stat().st_mtime_ns for p in dataset.rglob("*")}
    assert run_cli([str(dataset)]) == 1
    check_dataset(dataset / "alpha")
    assert tree_snapshot(dataset) == before
    assert {p: p.stat().st_mtime_ns for p in dataset.rglob("*")} == stats
    capsys.readouterr()


def test_cli_groups_problems_by_file_and_counts(dataset: Path, capsys: pytest.CaptureFixture) -> None:
    DEFECTS["label id outside space"][0](dataset)
    DEFECTS["depth missing"][0](dataset)
    DEFECTS["K bottom row"][0](dataset)
    assert run_cli([str(dataset)]) == 1
    out = capsys.readouterr().out.splitlines()
    files = [line for line in out if not line.startswith(" ")][:-1]
    assert files == [str(dataset / "alpha" / "depth" / "0001.png"), str(dataset / "alpha" / "label" / "0001.png"),
                     str(dataset / "alpha" / "cameras.json")]
    assert out[-1] == "3 problems in 3 files"


def test_cli_ok_summary(template: Path, capsys: pytest.CaptureFixture) -> None:
    assert run_cli([str(template)]) == 0
    assert capsys.readouterr().out.strip() == f"OK: 2 scenes, 11 views in {template}, no problems"


def test_in_memory_check_uses_the_same_rules() -> None:
    scene = small_scene("alpha", 6, "train", {"train": [0, 1, 2, 4, 5]}, 0)
    assert check_scene_object(scene) == []
    view = scene.read_view("0003")
    view.c2w[:3, :3] *= 2.0
    view.label[2, 2] = 77
    problems = check_scene_object(scene)
    assert sorted(p.file for p in problems) == ["alpha:0003", "alpha:0003"]
    assert any("not orthonormal" in p.what for p in problems) and any("[77]" in p.what for p in problems)
