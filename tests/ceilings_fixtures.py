"""Shared fixture of the ceilings and segmenter tests: tiny, exactly consistent scenes sharded once per module."""

from __future__ import annotations

from pathlib import Path

import pytest
import scene_fixtures

from sray.data_tools.shards.writer import write_shards


@pytest.fixture(scope="module")
def shards(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Two 12-view train scenes and one 12-view unseen test scene of 32x40 pixels (the encoder's minimum side),
    10 ranked neighbours per view."""
    root = tmp_path_factory.mktemp("ceilings")
    scenes = scene_fixtures.write_dataset(root / "scenes", [("a", 12, "train"), ("b", 12, "train"),
                                                            ("t", 12, "test")], height=32, width=40)
    write_shards(scenes, root / "shards", views_per_shard=6, neighbours=10, progress=False)
    return root / "shards"

