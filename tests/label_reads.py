"""A shared test helper: record which stored views' label maps a piece of code decodes."""

from __future__ import annotations

import numpy as np
import pytest

from sray.data_tools.loader import views as views_module
from sray.data_tools.loader.views import KEY_SEPARATOR


def record_label_reads(monkeypatch: pytest.MonkeyPatch) -> list[tuple[str, str]]:
    """Patch ``StoredView.label`` so that every decode appends its (scene, view id) to the returned list."""
    read: list[tuple[str, str]] = []
    original = views_module.StoredView.label

    def recording(self: views_module.StoredView) -> np.ndarray:
        key = self.where.rsplit(":", 1)[1]  # "<shard url>:<scene><KEY_SEPARATOR><view id>"
        scene, view = key.split(KEY_SEPARATOR, 1)
        read.append((scene, view))
        return original(self)

    monkeypatch.setattr(views_module.StoredView, "label", recording)
    return read
