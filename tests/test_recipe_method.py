"""The method registry, and the recipe "add a method": a per-scene class-prior predictor defined here,
registered, finetuned through the real per-scene code path on a tiny scene, then found in the
results table, the charts, the CLI choices and its reloaded artifact.

The class prior predicts one learned class and one colour for every ray, so its held-out mIoU has
a closed form, computed here from the raw held-out labels: with ``k`` predicted everywhere, IoU_k is
n_k / N (N labelled pixels, n_k of class k) and every other class present scores 0.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import cv2
import pytest
import torch
import torch.nn.functional as F
from fleet_fixtures import kept_point, one_thread, tiny_checkpoint, tiny_fleet_config  # noqa: F401
from safetensors.torch import load_file, save_file
from torch import Tensor, nn
from train_fixtures import tiny_shards  # noqa: F401

from sray.data_tools.loader.sample_types import EvalSample, TrainSample
from sray.data_tools.loader.shard_loader import make_eval_samples
from sray.jobs.fleet_cmd import register
from sray.model.losses import psnr_from_mse
from sray.model.view_render import strided_pixels
from sray.platform.finetune.fleet_report import results_table
from sray.platform.finetune.learners import Learner
from sray.platform.finetune.methods.method import ChartStyle, Method, SceneContext, SceneSetup
from sray.platform.finetune.methods.registry import METHODS, get_method, method_names, register_method
from sray.platform.finetune.scene_artifacts import checkpoint_sha256
from sray.platform.finetune.scene_finetune import SceneTask, finetune_scene
from sray.platform.viz.charts import curve_figure, write_fleet_charts

SCENE = "synth_test_000"
pytestmark = pytest.mark.usefixtures("one_thread")


class ClassPrior(nn.Module):
    """One class score vector and one colour, shared by every ray of the scene."""

    def __init__(self, n_classes: int) -> None:
        super().__init__()
        self.logits = nn.Parameter(torch.zeros(n_classes))
        self.colour = nn.Parameter(torch.zeros(3))

    def forward(self, n_rays: int) -> dict[str, Tensor]:
        return {"logits": self.logits.expand(n_rays, -1), "rgb": torch.sigmoid(self.colour).expand(n_rays, 3)}


class PriorLearner(Learner):
    """Fits the class prior to the training rays' labels and colours."""

    def __init__(self, net: ClassPrior, lr: float, ignore_id: int, device: torch.device) -> None:
        super().__init__(net.to(device), list(net.parameters()), lr, 0.0, "no", device, 5)
        self.ignore_id = ignore_id

    def loss(self, sample: TrainSample) -> tuple[Tensor, dict[str, Tensor]]:
        target = sample.target_label.to(self.device)
        out = self.net(len(target))
        labelled = (target != self.ignore_id).sum().clamp(min=1)
        ce = F.cross_entropy(out["logits"], target, ignore_index=self.ignore_id, reduction="sum") / labelled
        mse = F.mse_loss(out["rgb"], sample.target_rgb.to(self.device))
        return ce + mse, {"ce": ce.detach(), "psnr": psnr_from_mse(mse.detach())}

    def renderer(self, sample: EvalSample) -> Any:
        return lambda origins, dirs, near, far: {"fine": self.net(len(origins))}

    def snapshot(self) -> dict[str, Tensor]:
        return {k: v.detach().to("cpu", copy=True) for k, v in self.net.state_dict().items()}

    def restore(self, state: dict[str, Tensor]) -> None:
        self.net.load_state_dict(state)

    def save(self, path: Path, scene: str) -> None:
        save_file(self.snapshot(), str(path), metadata={"scene": scene})


def build_prior(ctx: SceneContext) -> SceneSetup:
    return SceneSetup(learner=PriorLearner(ClassPrior(ctx.n_classes), 0.1, ctx.ignore_id, ctx.device),
                      n_source=1, top_k=1)


def load_prior(artifact: Path, base_checkpoint: Path) -> nn.Module:
    tensors = load_file(str(artifact))
    net = ClassPrior(len(tensors["logits"]))
    net.load_state_dict(tensors)
    return net.eval()


PRIOR = Method(name="class-prior", summary="one learned class and colour per scene", build=build_prior,
               artifact_file="class_prior.safetensors", load=load_prior,
               style=ChartStyle(label="class prior", color="#2ca02c", marker="D"), uses_sources=False)


@pytest.fixture
def prior_method() -> Iterator[Method]:
    """The class-prior method, registered for one test."""
    register_method(PRIOR)
    yield PRIOR
    METHODS.pop(PRIOR.name)


def constant_miou(shards: Path, k: int, stride: int, ignore_id: int) -> float:
    """Dataset-level mIoU over the scene's held-out views of predicting class ``k`` at every pixel of the
    strided grid, from the raw labels: (n_k / N) / |classes present|, or 0 when k is absent."""
    labels = []
    for sample in make_eval_samples(shards, SCENE, split="test", n_source=1):
        h, w = sample.query_label.shape
        uv, _, _ = strided_pixels(h, w, stride)
        labels.append(sample.query_label[uv[:, 1].long(), uv[:, 0].long()])
    gt = torch.cat(labels)
    gt = gt[gt != ignore_id]
    present = gt.unique().tolist()
    return (float((gt == k).sum()) / len(gt)) / len(present) if k in present else 0.0


def test_builtin_methods_and_an_unknown_name():
    assert method_names()[:2] == ["sray", "semantic-nerf"]
    assert get_method("sray").uses_sources and get_method("sray").zero_shot is not None
    assert not get_method("semantic-nerf").uses_sources and get_method("semantic-nerf").zero_shot is None
    with pytest.raises(ValueError, match="unknown method 'nerf'; use one of sray, semantic-nerf, sray-rgbd, "
                                         "2d-transfer"):
        get_method("nerf")


def test_the_cli_reads_the_registry_without_importing_torch():
    code = ("import sys; import sray.jobs.fleet_cmd, sray.platform.finetune.methods.registry; "
            "print(sorted(m for m in ('torch', 'numpy', 'sray.platform.finetune.learners') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "[]"


def test_add_a_method_and_finetune_a_scene_with_it(prior_method, tiny_shards, tiny_checkpoint, tmp_path):
    cfg = tiny_fleet_config(max_steps=6, eval_every=3, patience=5)
    job = SceneTask(scene=SCENE, method=prior_method.name, checkpoint=str(tiny_checkpoint),
                   base_sha256=checkpoint_sha256(tiny_checkpoint), shards=str(tiny_shards), out_dir=str(tmp_path),
                   run=None, attempt=1, config=cfg)
    result = finetune_scene(job).result
    assert result["method"] == "class-prior" and result["status"] == "finished" and result["steps_used"] == 6
    assert [p["step"] for p in result["curve"]] == [0, 3, 6]
    assert result["protocol"]["n_source"] == 0  # a per-scene model: rendered from no source view

    # the stored artifact is the best evaluated state; its score has a closed form
    model = prior_method.load_artifact(tmp_path, tiny_checkpoint)
    assert result["artifact_bytes"] == (tmp_path / "class_prior.safetensors").stat().st_size
    stride, ignore_id = cfg.finetune.held_out.stride, 255
    expected_after = constant_miou(tiny_shards, int(model.logits.argmax()), stride, ignore_id)
    assert result["miou_after"] == pytest.approx(expected_after, abs=1e-9)
    assert result["miou_before"] == pytest.approx(constant_miou(tiny_shards, 0, stride, ignore_id), abs=1e-9)
    assert result["miou_after"] == kept_point(result["curve"], cfg.finetune.min_delta)["miou"]

    # the new method appears in the results table and in the charts, in its own colour and label
    assert f"| {SCENE} | class-prior | RGB | finished |" in results_table([result])
    paths = write_fleet_charts([result], tmp_path / "charts", METHODS)
    assert [p.name for p in paths][-1] == "miou_vs_artifact_bytes.png"
    rgb = torch.from_numpy(cv2.cvtColor(cv2.imread(str(paths[0])), cv2.COLOR_BGR2RGB)).int()
    colour = torch.tensor([int(PRIOR.style.color[i:i + 2], 16) for i in (1, 3, 5)])
    assert int(((rgb - colour).abs().amax(-1) <= 12).sum()) > 20
    legend = [t.get_text() for sub in curve_figure([result], "miou", "step", METHODS).subfigs for lg in sub.legends
              for t in lg.get_texts()]
    assert legend == ["class prior [RGB]"]  # with the inputs its protocol records

    # the CLI offers it while it is registered
    parser = argparse.ArgumentParser(prog="sray")
    register(parser.add_subparsers(dest="command"))
    args = parser.parse_args(["finetune-fleet", "--checkpoint", "C", "--data", "D", "--all-test",
                              "--methods", "sray", "class-prior"])
    assert args.methods == ["sray", "class-prior"]
