"""S-Ray overfits a tiny ray-cast room: a training view renders with mIoU above 0.9."""

from __future__ import annotations

import numpy as np
import torch
from toy_room import FAR, N_CLASSES, NEAR, make_room, miou, one_thread, overfit

from sray.model.config import SRayConfig
from sray.model.runtime import Runtime

STEPS = 120  # 128 rays, 8 + 8 samples, 4 source views per step


def test_miou_helper_on_a_known_case() -> None:
    gt = np.array([0, 0, 1, 1, 2])
    pred = np.array([0, 1, 1, 1, 0])
    # class 0: inter 1, union 3; class 1: inter 2, union 3; class 2: inter 0, union 1
    assert abs(miou(pred, gt, 3) - (1 / 3 + 2 / 3 + 0) / 3) < 1e-12


def test_overfits_a_training_view_of_a_small_scene() -> None:
    room = make_room((36, 48), focal=30.0)
    with one_thread():
        net = overfit(room, SRayConfig(n_classes=N_CLASSES, n_coarse=8, n_fine=8, n_source=4), STEPS)
        with torch.no_grad():
            src = net.encode(*room.sources())
            img = net.render_image(src, torch.tensor(room.K, dtype=torch.float32),
                                   torch.tensor(room.cams[4], dtype=torch.float32), room.hw, NEAR, FAR,
                                   Runtime(chunk=512))
    pred = img["fine"]["logits"].argmax(-1).numpy()
    score = miou(pred, room.views[4][1], N_CLASSES)
    assert score > 0.9, f"mIoU {score:.3f} after {STEPS} steps"
