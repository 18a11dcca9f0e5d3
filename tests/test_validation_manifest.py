"""One validation during training reads the shard manifest once and hands the parsed manifest down."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest
import torch
from train_fixtures import tiny_config, tiny_shards  # noqa: F401

from sray.data_tools.shards import manifest as manifest_module
from sray.data_tools.shards.manifest import Manifest
from sray.model.semantic_ray import SRayModel
from sray.platform.eval.view_scoring import score_views
from sray.platform.train.validation import validate


@pytest.fixture
def manifest_reads(monkeypatch: pytest.MonkeyPatch) -> dict[str, list[str]]:
    """Calls of ``read_manifest`` (wherever a module imported it) and parses of any manifest JSON."""
    seen: dict[str, list[str]] = {"read_manifest": [], "Manifest.from_json": []}
    read, parse = manifest_module.read_manifest, Manifest.from_json

    def counting_read(shards_dir: Path) -> Manifest:
        seen["read_manifest"].append(str(shards_dir))
        return read(shards_dir)

    def counting_parse(cls: type, d: dict, where: str = manifest_module.MANIFEST_NAME) -> Manifest:
        seen["Manifest.from_json"].append(where)
        return parse(d, where)

    for module in list(sys.modules.values()):
        if getattr(module, "__name__", "").startswith("sray.") and getattr(module, "read_manifest", None) is read:
            monkeypatch.setattr(module, "read_manifest", counting_read)
    monkeypatch.setattr(Manifest, "from_json", classmethod(counting_parse))
    return seen


def test_a_validation_reads_the_manifest_once(tiny_shards: Path, tmp_path: Path,
                                              manifest_reads: dict[str, list[str]]) -> None:
    """Both groups (held-out views of the train scenes, the unseen scene) are scored from one read."""
    cfg = tiny_config(tiny_shards, tmp_path)
    torch.manual_seed(0)
    net = SRayModel(cfg.model)
    metrics = validate(net, cfg, 10, None, tmp_path / "job", torch.device("cpu"))
    assert {k.split("/")[0] for k in metrics} == {"val", "zeroshot"}
    assert manifest_reads["read_manifest"] == [cfg.data.shards]
    assert len(manifest_reads["Manifest.from_json"]) == 1


def test_val_scenes_keeps_the_first_scenes_of_each_role(tiny_shards: Path, tmp_path: Path) -> None:
    """``data.val_scenes=1`` validates the first train scene by name only; 0 validates all of them."""
    from sray.data_tools.shards.manifest import read_manifest
    from sray.platform.train.validation import evaluate_group

    cfg = tiny_config(tiny_shards, tmp_path)
    torch.manual_seed(0)
    net = SRayModel(cfg.model).eval()
    manifest = read_manifest(Path(cfg.data.shards))
    train_names = sorted(n for n, e in manifest.scenes.items() if e.meta["role"] == "train")
    assert len(train_names) >= 2
    cfg.data.val_scenes = 1
    one, renders = evaluate_group(net, cfg, manifest, "train", torch.device("cpu"))
    assert {scene for scene, _ in renders} == {train_names[0]}
    cfg.data.val_scenes = 0
    _, renders = evaluate_group(net, cfg, manifest, "train", torch.device("cpu"))
    assert {scene for scene, _ in renders} == set(train_names)
    first = [(s, v) for s, v in renders if s == train_names[0]]
    assert one["miou"] == pytest.approx(score_views([v for _, v in first], cfg.model.n_classes,
                                                    cfg.model.ignore_id)["miou"])
