"""Fleet configuration: ``--set`` overrides, range checks, the CLI flags, the summary table."""

from __future__ import annotations

import argparse
import math

import pytest

from sray.jobs.fleet_cmd import chosen_methods, fleet_flags, register
from sray.platform.config.fleet_config import FleetConfig, apply_fleet_override, build_fleet_config
from sray.platform.finetune.fleet_report import human_bytes, results_table, summary_metrics


def test_overrides_parse_each_field_type():
    cfg = FleetConfig()
    for assignment in ("finetune.patience=7", "finetune.min_delta=0.05", "finetune.rays_per_batch=128",
                       "finetune.adapt=fine.classifier, coarse.geometry", "max_parallel=4",
                       "gpus_per_task=0.25", "nerf.skip_layer=none", "experiment=x"):
        apply_fleet_override(cfg, assignment)
    assert cfg.finetune.patience == 7 and cfg.finetune.min_delta == 0.05 and cfg.finetune.rays_per_batch == 128
    assert cfg.finetune.adapt == ("fine.classifier", "coarse.geometry")
    assert cfg.max_parallel == 4 and cfg.gpus_per_task == 0.25 and cfg.nerf.skip_layer is None
    assert cfg.experiment == "x"
    apply_fleet_override(cfg, "finetune.rays_per_batch=None")
    assert cfg.finetune.rays_per_batch is None


@pytest.mark.parametrize("assignment, message", [
    ("finetune.nope=1", "no field 'nope' in FinetuneSettings"),
    ("train.patience=1", "no section 'train'"),
    ("finetune.patience=two", "not a valid int"),
    ("finetune.patience=0", "finetune.patience is 0"),
    ("finetune.precision=fp16", "needs CUDA"),
    ("finetune.precision=fp8", "finetune.precision"),
    ("nerf.skip_layer=8", "nerf.skip_layer"),
    ("patience", "expected"),
])
def test_bad_overrides_name_the_field(assignment, message):
    with pytest.raises(ValueError, match=message):
        apply_fleet_override(FleetConfig(), assignment)


def _parse(argv: list[str]) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog="sray")
    register(parser.add_subparsers(dest="command"))
    return parser.parse_args(argv)


def test_cli_flags_map_onto_the_config():
    args = _parse(["finetune-fleet", "--checkpoint", "C", "--data", "D", "--all-test", "--max-parallel", "3",
                   "--gpus-per-task", "0.5", "--precision", "fp16", "--methods", "sray", "semantic-nerf",
                   "--tracker", "mlflow", "--segmenter", "seg", "--set", "finetune.max_steps=50"])
    cfg = build_fleet_config(fleet_flags(args), args.overrides)
    assert args.all_test and args.scenes is None and args.methods == ["sray", "semantic-nerf"]
    assert (cfg.max_parallel, cfg.gpus_per_task, cfg.finetune.precision, cfg.finetune.max_steps) == (3, 0.5, "fp16", 50)
    assert cfg.tracker == "mlflow" and FleetConfig().tracker == "mlflow"
    assert cfg.transfer.segmenter == "seg" and FleetConfig().transfer.segmenter == ""
    assert _parse(["finetune-fleet", "--checkpoint", "C", "--data", "D", "--all-test"]).methods == ["sray"]
    every = _parse(["finetune-fleet", "--checkpoint", "C", "--data", "D", "--all-test", "--method", "all"]).methods
    assert chosen_methods(every) == ["sray", "semantic-nerf", "sray-rgbd", "2d-transfer"]
    assert chosen_methods(["semantic-nerf", "sray", "semantic-nerf"]) == ["semantic-nerf", "sray"]
    with pytest.raises(SystemExit):  # not a registered method
        _parse(["finetune-fleet", "--checkpoint", "C", "--data", "D", "--all-test", "--methods", "nerf"])
    with pytest.raises(SystemExit):  # --scenes and --all-test exclude each other
        _parse(["finetune-fleet", "--checkpoint", "C", "--data", "D", "--all-test", "--scenes", "a"])


PROTOCOL = {"source_rule": "frustum-overlap v1", "n_source": 8, "stride": 2, "render": "full", "inputs": "rgb",
            "miou": "dataset-level, classes present in ground truth", "miou_per_image": "per-image mean"}
"""A fleet result's protocol descriptor (docs/CONTRACTS.md)."""


def _result(scene: str, method: str, status: str = "finished", **values: object) -> dict:
    base = {"scene": scene, "method": method, "status": status, "error": None, "attempts": 1, "steps_used": 10,
            "max_steps": 10, "stopped_early": False, "wall_s": 2.0, "miou_before": 0.1, "miou_after": 0.3,
            "psnr_after": 20.0, "artifact_bytes": 2048, "full_checkpoint_bytes": 204800, "child_run_id": "r",
            "protocol": PROTOCOL, "curve": []}
    return base | values


def test_summary_metrics_average_finished_scenes_only():
    results = [_result("a", "sray", miou_after=0.5, steps_used=4), _result("b", "sray", miou_after=0.2, steps_used=8),
               _result("c", "sray", "failed", miou_after=None, miou_before=None, psnr_after=None, artifact_bytes=None,
                       steps_used=0, error="boom"),
               _result("a", "semantic-nerf", miou_after=0.1)]
    m = summary_metrics(results)
    assert m["sray/finished"] == 2 and m["sray/failed"] == 1 and m["semantic-nerf/finished"] == 1
    assert m["sray/miou_after_mean"] == pytest.approx(0.35, abs=1e-12)
    assert m["sray/steps_used_mean"] == 6 and m["semantic-nerf/miou_after_mean"] == 0.1
    assert math.isclose(m["semantic-nerf/miou_before_mean"], 0.1)


def test_results_table_has_a_row_per_result():
    rows = [_result("a", "sray", stopped_early=True, steps_used=4),
            _result("b", "sray", "failed", error="InjectedFailure: x | y", artifact_bytes=None, protocol=None)]
    table = results_table(rows)
    assert "| a | sray | RGB | finished | 1 | 4 | 2.0 | 0.100 | 0.300 | 20.00 | 2.0 KiB | 1.00% | early stop" in table
    assert "| b | sray | - | failed |" in table and "InjectedFailure: x / y" in table
    lines = table.splitlines()
    last_row = max(i for i, line in enumerate(lines) if line.startswith("|"))
    assert lines[last_row + 1] == ""  # a blank line ends the Markdown table, then its caption
    assert lines[last_row + 2] == ("Protocol: sources: 8 per query, fixed, top-ranked by frustum-overlap v1; "
                                   "pixels: every 2nd in each direction (stride 2), so no SSIM; render: full; "
                                   "inputs: rgb; mIoU: dataset-level, classes present in ground truth; "
                                   "mIoU/img: per-image mean")
    nerf = PROTOCOL | {"source_rule": "none (per-scene model)", "n_source": 0}
    mixed = results_table([_result("a", "sray"), _result("a", "semantic-nerf", protocol=nerf)])
    captions = [line for line in mixed.splitlines() if line.startswith("Protocol")]
    assert [c.split(": sources: ")[0] for c in captions] == ["Protocol (sray)", "Protocol (semantic-nerf)"]
    assert "sources: none (per-scene model)" in captions[1]
    depth = results_table([_result("a", "sray"), _result("a", "2d-transfer", protocol=PROTOCOL | {"inputs": "rgbd"})])
    assert "| a | sray | RGB | finished |" in depth and "| a | 2d-transfer | RGB-D | finished |" in depth
    assert [human_bytes(n) for n in (None, 512, 1536, 3 * 2**20)] == ["-", "512 B", "1.5 KiB", "3.0 MiB"]
