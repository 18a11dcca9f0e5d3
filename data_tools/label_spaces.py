"""Label spaces shared by every reader, the procedural generator and the model's class count."""

from __future__ import annotations

SCANNET20: list[str] = ["wall", "floor", "cabinet", "bed", "chair", "sofa", "table", "door", "window", "bookshelf",
                         "picture", "counter", "desk", "curtain", "refrigerator", "shower curtain", "toilet", "sink",
                         "bathtub", "otherfurniture"]
"""The ScanNet benchmark's 20 classes, ids 0..19 in this order (NYU40 ids: :data:`SCANNET20_NYU40_IDS`)."""

SCANNET20_NYU40_IDS: list[int] = [1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 14, 16, 24, 28, 33, 34, 36, 39]
"""NYU40 id of each ScanNet-20 class, index-aligned with :data:`SCANNET20`."""

NYU40: list[str] = ["wall", "floor", "cabinet", "bed", "chair", "sofa", "table", "door", "window", "bookshelf",
                     "picture", "counter", "blinds", "desk", "shelves", "curtain", "dresser", "pillow", "mirror",
                     "floor mat", "clothes", "ceiling", "books", "refrigerator", "television", "paper", "towel",
                     "shower curtain", "box", "whiteboard", "person", "night stand", "toilet", "sink", "lamp",
                     "bathtub", "bag", "otherstructure", "otherfurniture", "otherprop"]
"""NYU40 class names; label id i holds NYU40 id i + 1 (NYU40 id 0 = unlabelled -> ignore)."""

LABEL_SPACES: dict[str, list[str]] = {"scannet20": SCANNET20, "nyu40": NYU40}
"""Known label spaces by name."""


def class_names(space: str) -> list[str]:
    """Class names of a known label space; ValueError names the known ones otherwise."""
    try:
        return list(LABEL_SPACES[space])
    except KeyError:
        raise ValueError(f"unknown label space {space!r}; known: {sorted(LABEL_SPACES)}") from None
