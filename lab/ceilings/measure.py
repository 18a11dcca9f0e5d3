"""Where zero-shot accuracy goes: ceiling rows scored on zero-shot evaluation's own views and sources.

Every row is scored on the same query views (each unseen test scene's ``test`` views, the first
``views_per_scene`` of them) with the same fixed source views (``make_eval_samples``: each query's
``n_source`` top-ranked neighbours in the scene's ``source`` split) and the same metric as ``sray eval``
(:mod:`sray.lab.ceilings.rows`). Asked for ``held_out`` scenes, the query views are instead the held-out
views of the first training scenes (the accuracy benchmark's held-out rule, sources from their ``train`` split):
the same question on rooms the model was trained on. The rows (:func:`row_descriptors`):

* ``a`` ground-truth source labels carried by ground-truth geometry (backward transfer with the query's
  depth and the occlusion test, :mod:`~sray.platform.eval.label_transfer`): the ceiling of any method that
  labels a query from its sources (an oracle);
* ``b`` the same transfer of the 2D segmenter's predictions on the source images (an oracle);
* ``c`` the segmenter's predictions splatted forward with the source depth (the ``2d-transfer`` method's own
  transfer, :func:`~sray.platform.eval.segmenter.source_depth_transfer`: the RGB-D protocol's inputs,
  nothing of the query but its camera);
* ``c-rgb`` the segmenter's predictions carried backward by the depth S-Ray renders for the query from the
  source images (the RGB protocol's inputs: without source depth there is no occlusion test);
* ``s`` S-Ray's own rendering of the query (``render``: the accuracy benchmark's zero-shot render by default),
  the row every other one is read against; its depth is row ``c-rgb``'s;
* ``d`` S-Ray's fine field at the ground-truth surface (:mod:`~sray.lab.ceilings.surface_field`, an oracle);
* ``e`` linear probes on frozen encoder features (:mod:`~sray.lab.probes.linear_probe`) of the
  checkpoint, of the segmenter and of a random initialisation: they read the query image itself, which
  S-Ray never sees;
* ``f`` the segmenter labelling the query image itself (it reads the query image, like the probes);
* ``f-src`` the segmenter labelling the source images, scored against their own labels, each source view of a
  scene once: with ``held_out`` these are the training scenes' ``train`` views, the images it was trained on, so
  the row beside ``f`` tells fitting from transfer within the same rooms.

Rows b, c, c-rgb, f and f-src need a segmenter folder; without one they (and its probe) are left out.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from itertools import islice
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch import Tensor
from tqdm import tqdm

from sray.data_tools.loader.sample_types import EvalSample
from sray.data_tools.loader.samples import ranked_candidates
from sray.data_tools.loader.shard_loader import make_eval_samples
from sray.data_tools.loader.views import StoredView, read_scene_views
from sray.data_tools.scene import SceneMeta
from sray.data_tools.shards.manifest import read_manifest
from sray.lab.ceilings.rows import CeilingRow, RowProtocol
from sray.lab.ceilings.surface_field import field_at_surface
from sray.lab.probes.linear_probe import LinearProbe, fit_probe, random_encoder
from sray.model.fast_render import FastRender
from sray.model.semantic_ray import SRayModel
from sray.platform.checkpoints.folders import read_meta
from sray.platform.checkpoints.model_loading import model_from_checkpoint
from sray.platform.eval.label_transfer import UNSEEN_RULE, LabelTransfer, transfer_labels
from sray.platform.eval.segmenter import Segmenter, load_segmenter, source_depth_transfer
from sray.platform.eval.view_scoring import encode_sources
from sray.platform.eval.zero_shot import select_scenes, training_scenes

ZERO_SHOT_RENDER = FastRender(pixel_stride=1, confidence=0.9)
"""S-Ray's render in rows s and c-rgb by default: the studies' zero-shot render (every pixel, a fine
pass where the coarse confidence is below 0.9)."""

TIE_RULE = "majority of the sources that see a pixel; a tie goes to the label of the best-ranked source among them"


def row_descriptors(with_segmenter: bool, rgbd: bool) -> list[tuple[str, str, RowProtocol]]:
    """(key, title, protocol) of every row measured, in table order; ``rgbd``: the checkpoint's model reads
    the source depth (``model.inputs='rgbd'``)."""
    rows = [("a", "GT source labels, GT geometry (source-based ceiling)",
             RowProtocol("source GT labels", "backward from query GT depth, occlusion-tested", query_depth=True,
                         source_depth=True, source_labels=True))]
    if with_segmenter:
        rows += [("b", "segmenter on sources, GT geometry",
                  RowProtocol("segmenter on source images", "backward from query GT depth, occlusion-tested",
                              query_depth=True, source_images=True, source_depth=True, segmenter=True)),
                 ("c", "segmenter on sources, source-depth splatting (2d-transfer)",
                  RowProtocol("segmenter on source images", "forward splatting of source depth, z-buffered",
                              source_images=True, source_depth=True, segmenter=True)),
                 ("c-rgb", "segmenter on sources, S-Ray's rendered depth (RGB)",
                  RowProtocol("segmenter on source images", "backward from S-Ray's rendered query depth, no "
                              "occlusion test", source_images=True, source_depth=rgbd, segmenter=True,
                              rendered_depth=True))]
    rows.append(("s", "S-Ray zero-shot render", RowProtocol("S-Ray render", "—", source_images=True,
                                                            source_depth=rgbd)))
    rows.append(("d", "S-Ray fine field at the GT surface",
                 RowProtocol("S-Ray fine field", "one ray point at the query GT depth", query_depth=True,
                             source_images=True, source_depth=rgbd)))
    probes = [("e", "linear probe, checkpoint encoder (reads the query image)")]
    if with_segmenter:
        probes.append(("e-seg", "linear probe, segmenter encoder (reads the query image)"))
    probes.append(("e-rand", "linear probe, random encoder (reads the query image)"))
    rows += [(k, t, RowProtocol("linear probe on the query image's features", "—", query_image=True))
             for k, t in probes]
    if with_segmenter:
        rows += [("f", "segmenter on the query image (reads the query image)",
                  RowProtocol("segmenter on the query image", "—", query_image=True, segmenter=True)),
                 ("f-src", "segmenter on the source images, scored on their own labels (not the query)",
                  RowProtocol("segmenter on the source images", "—", source_images=True, segmenter=True))]
    return rows


def source_ids(sample: EvalSample, views: dict[str, StoredView], meta: SceneMeta, n_source: int) -> list[str]:
    """The ids of ``sample``'s source views (ranked ``source``-split neighbours of test scenes, ``train``-split
    of train scenes, as ``make_eval_samples`` picks them), checked against the sample's source cameras."""
    allowed = set(meta.splits["source" if meta.role == "test" else "train"])
    ids = ranked_candidates(views[sample.query_id], allowed, n_source)
    cameras = torch.from_numpy(np.stack([views[i].c2w for i in ids])).float()
    if not torch.equal(cameras, sample.sources.c2w):
        raise RuntimeError(f"scene {sample.scene!r}, view {sample.query_id!r}: the source ids {ids} do not match "
                           "the evaluation sample's sources; make_eval_samples changed its source rule, update "
                           "sray.lab.ceilings.measure.source_ids to match it")
    return ids


def timed(fn: Callable[[], Any]) -> tuple[Any, float]:
    """``fn()`` and the wall seconds it took."""
    start = time.perf_counter()
    out = fn()
    return out, time.perf_counter() - start


@dataclass
class ViewScorer:
    """What predicts the rows of one view: the checkpoint, the segmenter, the probes and the transfer's test."""

    net: SRayModel
    """The checkpoint's S-Ray network (eval mode, CPU)."""
    segmenter: Segmenter | None
    """The 2D segmenter of rows b, c, c-rgb, f and f-src, or None."""
    probes: dict[str, LinearProbe]
    """Fitted probes by row key."""
    tolerance: float
    """The occlusion test's relative depth agreement."""
    render: FastRender | None
    """S-Ray's render of row s (and of row c-rgb's depth): the fast mode's settings, None = the full render."""
    scored_sources: set[tuple[str, str]] = field(default_factory=set)
    """(scene, view id) of the source views row f-src has scored (each once)."""

    def score(self, rows: dict[str, CeilingRow], sample: EvalSample, gt_sources: Tensor, ids: list[str]) -> None:
        """Predict every row for ``sample`` and add it to ``rows``; gt_sources (m, H, W) int64 are the ground-truth
        labels of the sample's source views, ``ids`` their m view ids (row f-src scores each source view of a scene
        once)."""
        cfg = self.net.cfg
        src, gt, scene, hw = sample.sources, sample.query_label, sample.scene, tuple(sample.query_label.shape)
        geometry = (src.K, src.c2w, src.depth, sample.query.K, sample.query.c2w, hw)

        def backward(labels: Tensor) -> LabelTransfer:
            return transfer_labels(labels, *geometry, "backward", tolerance=self.tolerance, ignore_id=cfg.ignore_id,
                                   query_depth=sample.query_depth)

        if len(ids) != gt_sources.shape[0]:
            raise ValueError(f"ceilings: scene {scene!r}, view {sample.query_id!r}: {len(ids)} source view ids for "
                             f"{gt_sources.shape[0]} source label maps; give one id per source view")
        oracle, seconds = timed(lambda: backward(gt_sources))
        rows["a"].add(scene, oracle.labels, gt, cfg.n_classes, cfg.ignore_id, seconds, oracle.seen)
        encoded, encode_seconds = timed(lambda: encode_sources(self.net, sample, torch.device("cpu")))
        rendered, render_seconds = timed(lambda: self.net.render_image(encoded, sample.query.K, sample.query.c2w, hw,
                                                                       sample.near, sample.far,
                                                                       fast=self.render)["fine"])
        render_seconds += encode_seconds
        rows["s"].add(scene, rendered["logits"].argmax(-1), gt, cfg.n_classes, cfg.ignore_id, render_seconds)
        if self.segmenter is not None:
            seg_labels, seg_seconds = timed(lambda: self.segmenter.predict(src.rgb))  # (m, H, W)
            guided, seconds = timed(lambda: backward(seg_labels))
            rows["b"].add(scene, guided.labels, gt, cfg.n_classes, cfg.ignore_id, seg_seconds + seconds, guided.seen)
            splat, seconds = timed(lambda: source_depth_transfer(seg_labels, src, sample.query, self.tolerance,
                                                                 cfg.ignore_id))  # the 2d-transfer method's
            rows["c"].add(scene, splat.labels, gt, cfg.n_classes, cfg.ignore_id, seg_seconds + seconds, splat.seen)
            carried, seconds = timed(lambda: transfer_labels(seg_labels, src.K, src.c2w, None, sample.query.K,
                                                             sample.query.c2w, hw, "backward", ignore_id=cfg.ignore_id,
                                                             query_depth=rendered["depth"].double()))
            rows["c-rgb"].add(scene, carried.labels, gt, cfg.n_classes, cfg.ignore_id,
                              seg_seconds + render_seconds + seconds, carried.seen)
            direct, seconds = timed(lambda: self.segmenter.predict(sample.query_rgb.permute(2, 0, 1)[None])[0])
            rows["f"].add(scene, direct, gt, cfg.n_classes, cfg.ignore_id, seconds)
            for j, view_id in enumerate(ids):
                if (scene, view_id) not in self.scored_sources:
                    self.scored_sources.add((scene, view_id))
                    rows["f-src"].add(scene, seg_labels[j], gt_sources[j], cfg.n_classes, cfg.ignore_id,
                                      seg_seconds / len(ids))
        pred, seconds = timed(lambda: field_at_surface(self.net, encoded, sample.query.K, sample.query.c2w,
                                                       sample.query_depth, sample.near, sample.far))
        rows["d"].add(scene, pred, gt, cfg.n_classes, cfg.ignore_id, encode_seconds + seconds, oracle.seen)
        query_rgb = sample.query_rgb.permute(2, 0, 1)[None]  # (1, 3, H, W)
        for key, probe in self.probes.items():
            pred, seconds = timed(lambda: probe.predict(query_rgb)[0])  # noqa: B023 - called at once
            rows[key].add(scene, pred, gt, cfg.n_classes, cfg.ignore_id, seconds)


def fit_probes(net: SRayModel, segmenter: Segmenter | None, shards: Path, steps: int, max_views: int,
               seed: int) -> dict[str, LinearProbe]:
    """Probes on the checkpoint's encoder (``e``), the segmenter's (``e-seg``, when given) and a random one
    (``e-rand``, initialised under ``seed``), all fitted alike, their heads initialised under ``seed``."""
    encoders = {"e": net.encoder, "e-seg": None if segmenter is None else segmenter.encoder,
                "e-rand": random_encoder(net.cfg.feat_dim, seed, net.cfg.encoder_width)}
    return {key: fit_probe(encoder, shards, net.cfg, steps=steps, max_views=max_views, seed=seed)
            for key, encoder in encoders.items() if encoder is not None}


def measure_ceilings(checkpoint: Path, shards: Path, *, n_source: int = 8, views_per_scene: int = 0,
                     segmenter: Path | None = None, probe_steps: int = 300, probe_views: int = 64,
                     tolerance: float = 0.05, seed: int = 0, render: FastRender | None = ZERO_SHOT_RENDER,
                     held_out: int = 0, progress: bool = True) -> dict[str, Any]:
    """Score every row (module doc) on the unseen test scenes of ``shards`` (or, ``held_out`` > 0, on the held-out
    views of its first ``held_out`` training scenes); returns the JSON-ready report.

    ``views_per_scene``: the first test views of each scene (0 = all); ``segmenter``: a folder written by
    :func:`~sray.platform.eval.segmenter_training.train_segmenter`; ``probe_steps``/``probe_views``: the
    probes' fit; ``tolerance``: the occlusion test's relative depth agreement; ``seed``: the random encoder's and
    the probe heads' initialisation; ``render``: S-Ray's render of rows s and c-rgb (None = the full render). Runs on
    the CPU.
    """
    checkpoint, shards = Path(checkpoint).resolve(), Path(shards).resolve()
    net, cfg = model_from_checkpoint(checkpoint)
    step = int(read_meta(checkpoint if checkpoint.is_dir() else checkpoint.parent)["step"])
    names, metas = select_scenes(shards, training_scenes(shards, held_out) if held_out else None)
    wrong = [s for s in names if len(metas[s]["class_names"]) != cfg.model.n_classes]
    if wrong:
        raise ValueError(f"{shards / 'manifest.json'}: scenes {wrong} have {len(metas[wrong[0]]['class_names'])} "
                         f"classes, the checkpoint's model predicts {cfg.model.n_classes}; measure on data of the "
                         "label space the model was trained on")
    manifest = read_manifest(shards)
    seg, record = load_segmenter(segmenter) if segmenter is not None else (None, None)
    if seg is not None and seg.cfg.n_classes != cfg.model.n_classes:
        raise ValueError(f"{segmenter}: the segmenter predicts {seg.cfg.n_classes} classes, the checkpoint "
                         f"{cfg.model.n_classes}; train both on the same label space")
    scorer = ViewScorer(net, seg, fit_probes(net, seg, shards, probe_steps, probe_views, seed), tolerance, render)
    seg_budget = record.budget() if record else ""
    rendered = f"checkpoint step {step}, {'full' if render is None else render.describe()} render"
    budgets = {"b": seg_budget, "c": seg_budget, "c-rgb": f"{seg_budget}; depth: {rendered}", "s": rendered,
               "f": seg_budget, "f-src": seg_budget,
               "d": f"checkpoint step {step}",
               **{k: f"{p.budget()}; encoder: " + {"e": f"checkpoint step {step}", "e-seg": seg_budget,
                                                   "e-rand": f"random init, seed {seed}"}[k]
                  for k, p in scorer.probes.items()}}
    rows = {k: CeilingRow(k, t, p, budgets.get(k, ""), geometric=p.geometry != "—")
            for k, t, p in row_descriptors(seg is not None, cfg.model.inputs == "rgbd")}
    bar = tqdm(desc="ceilings views", unit="view", disable=not progress)
    for scene in names:
        meta = SceneMeta.from_json(metas[scene])
        views = read_scene_views(shards, manifest.scenes[scene])
        samples = make_eval_samples(shards, scene, split="test", n_source=n_source, manifest=manifest)
        for sample in islice(samples, views_per_scene or None):
            ids = source_ids(sample, views, meta, n_source)
            scorer.score(rows, sample, torch.from_numpy(np.stack([views[i].label() for i in ids]).astype(np.int64)),
                         ids)
            bar.update(1)
    bar.close()
    return {"checkpoint": str(checkpoint), "checkpoint_step": step, "shards": str(shards), "scenes": names,
            "held_out": held_out, "n_source": n_source, "views_per_scene": views_per_scene, "tolerance": tolerance,
            "render": "full" if render is None else render.describe(),
            "source_rule": "make_eval_samples: each query view's top-ranked neighbours in its scene's "
                           + ("train split" if held_out else "source split"),
            "unseen_rule": UNSEEN_RULE, "tie_rule": TIE_RULE,
            "coverage_of_d": "row d's coverage is row a's (the same geometry)",
            "segmenter": None if record is None else {"folder": str(segmenter), **record.training},
            "rows": [row.summary(cfg.model.n_classes) for row in rows.values()]}
