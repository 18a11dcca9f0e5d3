"""Render a planned fly-through into videos, ``frames.json`` and ``protocol.txt`` (docs/render.md); a frame with the
last one's set of sources reuses their encoding, reordered (the encoder sees each view alone)."""

from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Any

import numpy as np
import torch

from sray.data_tools.loader.sample_types import QueryCamera, SceneQuery, SourceViews
from sray.model.fast_render import FastRender
from sray.model.runtime import Runtime
from sray.model.semantic_ray import SRayModel, SourceSet
from sray.platform.common.eval_protocol import EvalProtocol
from sray.platform.common.progress import make_progress
from sray.platform.render.frames import render_frame
from sray.platform.render.panels import compose_panels, panel_layout
from sray.platform.render.plan import FlythroughPlan
from sray.platform.render.sources import SourcePicker
from sray.platform.render.video import VideoSet

STEM = "flythrough"  # file name stem of the videos
FRAMES_FILE = "frames.json"  # per-frame poses, intrinsics and sources, with the request and the protocol
PROTOCOL_FILE = "protocol.txt"  # the protocol line beside the videos


class Flythrough:
    """A fly-through ready to render: the model, the plan, the source picker and the protocol, all checked."""

    def __init__(self, net: SRayModel, plan: FlythroughPlan, n_source: int, fast: FastRender | None = None,
                 runtime: Runtime = Runtime()) -> None:
        """Check that ``plan``'s scene fits ``net`` and gives ``n_source`` sources per frame (ValueError naming the
        manifest or the scene). ``fast``: the fast mode (None: full render); ``runtime``: implementation, chunk."""
        manifest = plan.shards / "manifest.json"
        names = plan.meta.class_names
        if len(names) != net.cfg.n_classes:
            raise ValueError(f"{manifest}: scene {plan.meta.name!r} has {len(names)} classes, "
                             f"the model predicts {net.cfg.n_classes}; render data of the model's label space")
        self.net, self.plan, self.fast, self.runtime = net.eval(), plan, fast, runtime
        self.picker = SourcePicker(plan.views, plan.meta, n_source)
        self.protocol = EvalProtocol.from_manifest(plan.manifest, n_source, 1, str(manifest),
                                                   net.cfg.inputs).rendered_by(fast)
        self.layout = panel_layout(plan.path.hw, len(names))
        self._encoded: tuple[list[str], torch.device, SourceSet] | None = None

    def _encode(self, ids: list[str], sources: SourceViews, device: torch.device) -> SourceSet:
        """The encoding of ``sources`` (the views ``ids``, in that order); one of the same set of views is reused."""
        if self._encoded is None or set(self._encoded[0]) != set(ids) or self._encoded[1] != device:
            src = sources.to(device)
            self._encoded = ids, device, self.net.encode(src.rgb, src.K, src.c2w, src.depth)
        done, _, encoded = self._encoded
        return encoded if done == ids else encoded.select([done.index(v) for v in ids])

    @torch.no_grad()
    def picture(self, index: int, device: torch.device, label: str = "") -> tuple[np.ndarray, list[str]]:
        """Frame ``index``'s uint8 panel picture (``label`` in its title) and source ids, best first; ``net`` on
        ``device``. Calls reuse the last encoding, so change the weights only between :meth:`render` calls."""
        meta, path = self.plan.meta, self.plan.path
        ids = self.picker.choose(path.K[index], path.c2w[index], path.hw)
        query = QueryCamera(K=torch.from_numpy(path.K[index]).float(), c2w=torch.from_numpy(path.c2w[index]).float())
        sample = SceneQuery(scene=meta.name, query_id=f"frame {index}", sources=self.picker.sources(ids),
                            query=query, near=float(meta.near), far=float(meta.far))
        renderer = self.net.ray_renderer(self._encode(ids, sample.sources, device), self.fast, self.runtime)
        frame = render_frame(renderer, sample, path.hw, self.runtime.chunk, device, self.fast)
        title = " | ".join(filter(None, [meta.name, label, path.describe, f"frame {index + 1}/{len(path)}"]))
        picture = compose_panels(frame.rgb.numpy(), frame.label.numpy(), frame.depth.numpy(), frame.confidence.numpy(),
                                 meta.class_names, meta.near, meta.far, title, meta.ignore_id)
        return picture, ids

    def render(self, out_dir: Path, device: torch.device, *, about: dict[str, Any] | None = None, label: str = "",
               progress: bool = True) -> dict[str, Any]:
        """Render every frame into ``out_dir``; ``about`` (checkpoint, artifact) goes into frames.json, ``label``
        into every title. ``{"files": {name: path}, "n_frames", "size", "frames_per_s", "protocol"}``."""
        plan, path, n = self.plan, self.plan.path, len(self.plan.path)
        self.net.to(device)
        self._encoded = None  # the weights may have changed since the last render (a fleet's clip after finetuning)
        frames: list[dict[str, Any]] = []
        bar = make_progress(progress, total=n, desc=f"render {plan.meta.name}")
        start = time.perf_counter()
        with VideoSet(out_dir, STEM, plan.fps, self.layout.size, n) as videos:
            for i in range(n):
                picture, ids = self.picture(i, device, label)
                videos.write(picture)
                frames.append({"index": i, "c2w": path.c2w[i].tolist(), "K": path.K[i].tolist(), "source_ids": ids})
                bar.update(1)
                bar.set_postfix(frames_per_s=f"{(i + 1) / (time.perf_counter() - start):.2f}")
            bar.close()
            rate = n / (time.perf_counter() - start)
            record = {"scene": plan.meta.name, "path": path.describe,
                      "size": {"height": path.hw[0], "width": path.hw[1]},
                      "panel_size": {"height": self.layout.size[0], "width": self.layout.size[1]}, "fps": plan.fps,
                      "n_frames": n, "model": about or {}, "near": plan.meta.near, "far": plan.meta.far,
                      "frames_per_s": rate, "camera_axes": "OpenCV (x right, y down, z forward), camera-to-world",
                      "protocol": self.protocol.to_json(), "protocol_line": self.protocol.describe(), "frames": frames}
            files = videos.finish({FRAMES_FILE: (json.dumps(record, indent=1) + "\n").encode(),
                                   PROTOCOL_FILE: (self.protocol.describe() + "\n").encode()})
        return {"files": {k: str(v) for k, v in files.items()}, "n_frames": n, "size": self.layout.size,
                "frames_per_s": rate, "protocol": self.protocol.to_json()}
