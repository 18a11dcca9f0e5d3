"""The view-split rules every scene source shares (docs/data.md, "Splits"): train scenes hold out every 20th view
for validation; test scenes follow the paper's protocol (20 nearby views: 8 source, 8 finetune, 4 test)."""

from __future__ import annotations

PROTOCOL_WINDOW = 20  # views of a test scene's evaluation window
PROTOCOL_BLOCK = ("finetune", "source", "test", "source", "finetune")  # splits of five consecutive window views
HOLDOUT_EVERY = 20  # default hold-out period of train scenes


def train_splits(view_ids: list[str], holdout_every: int = HOLDOUT_EVERY) -> dict[str, list[str]]:
    """``train`` + held-out ``test`` (every ``holdout_every``-th view, offset by half a period); 0 = no hold-out."""
    if holdout_every <= 0:
        return {"train": list(view_ids)}
    held = {i for i in range(len(view_ids)) if i % holdout_every == holdout_every // 2}
    return {"train": [v for i, v in enumerate(view_ids) if i not in held],
            "test": [v for i, v in enumerate(view_ids) if i in held]}


def protocol_splits(view_ids: list[str], start: int | None) -> tuple[list[str], dict[str, list[str]]]:
    """The 20-view window from ``start`` (None: centred) and its source/finetune/test splits."""
    if len(view_ids) < PROTOCOL_WINDOW:
        raise ValueError(f"a test scene needs {PROTOCOL_WINDOW} views for the source/finetune/test protocol, "
                         f"got {len(view_ids)}; give it more views (--views, or a smaller --frame-skip)")
    start = (len(view_ids) - PROTOCOL_WINDOW) // 2 if start is None else start
    if not 0 <= start <= len(view_ids) - PROTOCOL_WINDOW:
        raise ValueError(f"window start {start} out of range 0..{len(view_ids) - PROTOCOL_WINDOW}")
    window = view_ids[start:start + PROTOCOL_WINDOW]
    return window, {name: [v for k, v in enumerate(window) if PROTOCOL_BLOCK[k % 5] == name]
                    for name in ("source", "finetune", "test")}
