"""``sray bench speed-accuracy`` on one checkpoint or several (a recipe's seeds): settings, ``--methods`` rows, the rule
per checkpoint and on their mean; chart and tables (default set, or ``--settings``) into docs/benchmarks.md, logged."""

from __future__ import annotations

import os
import textwrap
import time
from pathlib import Path

from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from sray.data_tools.atomic import save_png
from sray.jobs.bench.render_default import MAX_CLASS_LOSS, MAX_MIOU_LOSS, MIN_CLASS_SHARE, DefaultChoice
from sray.jobs.bench.speed_accuracy import SPEED, measure, paired_settings, pareto, select_settings, table, table_title
from sray.jobs.bench.speed_classes import class_table, mean_rows
from sray.jobs.bench.speed_methods import method_models
from sray.jobs.bench.speed_verdict import checkpoint_label, rule_choice, todays_settings, verdict_table
from sray.jobs.methods.flags import flags_reading
from sray.model.ray_chunks import CUDA_RENDER_RAYS
from sray.platform.common.bench_doc import bench_dir, record
from sray.platform.common.eval_protocol import EvalProtocol, inputs_name
from sray.platform.finetune.methods.registry import get_method
from sray.platform.tracking.registry import get_tracker

FAST, FULL = "tab:blue", "tab:gray"  # the chart's S-Ray fast-render and full-render settings


def report(rows: list[dict], choice: DefaultChoice | None) -> str:
    """The main table (with the rule's column when there is a ``choice``) and the per-class table."""
    classes = (f"IoU per class (%, each class's IoU over every rendered test view; the classes holding at least "
               f"{100 * MIN_CLASS_SHARE:g}% of the labelled test pixels):")
    return "\n\n".join([table(rows, choice), classes, class_table(rows, choice.chosen if choice else None)])


def run_speed_accuracy(checkpoints: list[Path], shards: Path, views_per_scene: int, doc: Path, tracker: str,
                       tracking_uri: str, checkpoint_rgbd: Path | None = None, names: list[str] | None = None,
                       methods: list[str] | None = None, segmenter: Path | None = None,
                       store: Path | None = None) -> str:
    """Measure the settings ``names`` (None: the defaults) and the ``methods``' zero-shot models (with ``segmenter``
    where one reads it) on each of ``checkpoints``, apply the rule to each and their mean, write and log the chart and
    section; returns the section. ValueError or FileNotFoundError, before any measuring, for a method not buildable."""
    shards, methods = Path(shards), list(methods or [])
    others = [method_models(methods, Path(c), segmenter) for c in checkpoints]
    settings = paired_settings(select_settings(names), (m.inputs for m in others[0].values()))
    rgbd = Path(checkpoint_rgbd) if checkpoint_rgbd else None
    runs = [measure(Path(c), shards, settings, views_per_scene, checkpoint_rgbd=rgbd, others=o, store=store)
            for c, o in zip(checkpoints, others, strict=True)]
    rows = runs[0] if len(runs) == 1 else mean_rows(runs)
    labels = [checkpoint_label(c) for c in checkpoints] + ([f"mean of {len(runs)}"] if len(runs) > 1 else [])
    choices = [rule_choice(r, settings) for r in (runs if len(runs) == 1 else [*runs, rows])]
    if len(runs) > 1:
        for label, run, choice in zip(labels[:len(runs)], runs, choices[:len(runs)], strict=True):
            print(f"\n[speed-accuracy] {label}\n\n{report(run, choice)}", flush=True)
    body = report(rows, choices[-1])
    today = todays_settings(settings)
    if choices[-1] is not None:
        rule = (f"Default render by the rule: the fastest setting offered that loses at most {MAX_MIOU_LOSS:g} "
                f"point of mIoU and at most {MAX_CLASS_LOSS:g} points on every class holding at least "
                f"{100 * MIN_CLASS_SHARE:g}% of the labelled test pixels, against '{rows[0]['name']}':")
        body += "\n\n" + rule + "\n\n" + verdict_table(labels, choices, today)
    protocol = (EvalProtocol.from_shards(shards, 8, 1).describe().replace("render: full", "render: per setting")
                .replace("inputs: rgb", "inputs: per row (the table's inputs column)"))
    png = chart(rows, bench_dir(doc, SPEED) / ("chosen.png" if names else "default.png"), protocol)
    section = record(SPEED, table_title(names), body, doc,
                     notes(rows, checkpoints, shards, views_per_scene, checkpoint_rgbd, today, protocol, png, doc))
    tracking = get_tracker(tracker, tracking_uri)
    run = tracking.start_run("sray-bench", f"speed-accuracy-{time.strftime('%Y%m%d-%H%M%S')}",
                             tags={"sray.kind": "bench", "sray.protocol": protocol})
    with tracking.logger(run) as logger:
        logger.log_params({"checkpoint": ", ".join(str(c) for c in checkpoints),
                           "checkpoint_rgbd": str(checkpoint_rgbd or "same weights"), "shards": str(shards),
                           "views_per_scene": views_per_scene, "methods": ", ".join(methods) or "none",
                           "segmenter": str(segmenter or "none"),
                           "default_by_rule": choices[-1].chosen if choices[-1] is not None else "not applied"})
        for i, r in enumerate(rows):
            logger.log_metrics({"miou": r["miou"], "psnr": r["psnr"], "cpu_s_per_view": r["s_per_view"],
                                "wall_s_per_view": r["wall_s_per_view"]}, i)
            if len(runs) > 1:
                logger.log_metrics({f"ckpt{k}/miou": run_rows[i]["miou"] for k, run_rows in enumerate(runs)}, i)
        logger.log_artifact(png)
    return section


def notes(rows: list[dict], checkpoints: list[Path], shards: Path, views_per_scene: int,
          checkpoint_rgbd: Path | None, today: dict[str, str | None], protocol: str, png: Path, doc: Path) -> str:
    """The notes under the section's tables: what was measured, what each setting means, today's defaults, the chart."""
    rgbd_by = f"`{checkpoint_rgbd}` (trained with model.inputs=rgbd)" if checkpoint_rgbd else "the same weights"
    own_fine = ", ".join(sorted({f"`fine_samples={r['fine_samples']}`" for r in rows if r["setting"] is not None
                                 and not r["setting"]["fine_samples"] and not r["setting"]["fast"]})) or "-"
    which = ("every test view" if views_per_scene <= 0 else "the first test view" if views_per_scene == 1 else
             f"the first {views_per_scene} test views")
    defaults = "; ".join(f"{user} '{name}'" if name else f"{user} not measured" for user, name in today.items())
    named = ", ".join(f"`{c}`" for c in checkpoints)
    whose = (f"Checkpoint {named}" if len(checkpoints) == 1 else
             f"Checkpoints {named}; rows, per-class IoU and the rule's last line are the mean over them")
    return (f"{whose}; {which} of each unseen scene of `{shards}`, the same views for every setting (paired); mIoU "
            f"dataset-level per scene, then the mean over scenes; per-class IoU dataset-level over all those views "
            f"together (one confusion matrix). CPU s / view is the CPU time this process spent (all its threads) "
            f"encoding the sources, rendering and scoring one whole view (`sray eval`'s loop), the speed measure here "
            f"because other jobs may share the cores (on a quiet machine wall time is about CPU time / torch "
            f"threads); wall s / view is shown beside it. Settings: 'full, reference path' is the unoptimised path "
            f"(`impl=reference`, chunks of {CUDA_RENDER_RAYS} rays) with the checkpoint's samples; 'full' is the "
            f"optimised path (chunks by device: 256 rays on a CPU), equal to it within fp32 tolerance. Both render as "
            f"the checkpoint was trained ({own_fine}), as `sray eval --render full` does; 'fine union' makes the fine "
            f"pass re-evaluate the coarse depths too, 'fine new only' evaluates the resampled depths alone. 'fast sS "
            f"cC': the fast render mode (`sray.model.fast_render`), rays every S-th pixel upsampled bilinearly, fine "
            f"pass (resampled depths only) where the coarse confidence is below C. 'rgbd': the coarse samples placed "
            f"by the sources' depth (docs/model.md, RGB-D mode), rendered by {rgbd_by}. The default-render rule "
            f"(`jobs/bench/render_default.py`) is offered the settings that differ from the first row only in how "
            f"they render (full or fast, implementation): the same sources, inputs, samples and precision; 'not "
            f"offered' marks the others, and it never reads another method's row. {method_sentence(rows)}Today's "
            f"defaults render as: {defaults} (validation and the fleet score a strided grid of their own and render "
            f"its every pixel: per scored pixel, pixel stride 1). Protocol: {protocol}.\n\n"
            f"![speed-accuracy]({os.path.relpath(png, doc.parent)})")


def method_sentence(rows: list[dict]) -> str:
    """What the rows of other registered methods are (empty when there are none), for the notes."""
    others = [r for r in rows if r["setting"] is None]
    if not others:
        return ""
    named = ", ".join(f"'{r['name']}' ({inputs_name(r['inputs'])}, built from "
                      f"{', '.join(f'`{f}`' for f in flags_reading(get_method(r['method']).eval_reads))})"
                      for r in others)
    return (f"Other registered methods' rows ({named}): each method's zero-shot model as `sray eval --method NAME` "
            "builds it, full render, scored on the same views with the same sources as the S-Ray setting of its "
            "inputs listed just above it (S-Ray's RGB-D row beside an RGB-D method) and timed the same way, "
            "everything it runs per view included. ")


def chart(rows: list[dict], path: Path, protocol: str) -> Path:
    """mIoU (%) against CPU seconds per view (log), the Pareto front joined, points numbered and named in a key."""
    fig = Figure(figsize=(11, 6.5))
    FigureCanvasAgg(fig)
    ax = fig.add_axes((0.07, 0.1, 0.56, 0.74))
    others = {}
    for i, r in enumerate(rows, 1):
        if r["setting"] is None:
            method = get_method(r["method"])
            style = others.setdefault(r["method"], method.zero_shot or method.style)
            ax.scatter(r["s_per_view"], r["miou"], s=60, color=style.color, marker=style.marker)
        else:
            ax.scatter(r["s_per_view"], r["miou"], s=40, color=FAST if r["setting"]["fast"] else FULL)
        ax.annotate(str(i), (r["s_per_view"], r["miou"]), textcoords="offset points", xytext=(4, 3), fontsize=8)
    front = pareto(rows)
    ax.plot([r["s_per_view"] for r in front], [r["miou"] for r in front], color="tab:orange", lw=1.5,
            label="Pareto front")
    ax.scatter([], [], color=FAST, label="S-Ray, fast render mode")
    ax.scatter([], [], color=FULL, label="S-Ray, full render")
    for style in others.values():
        ax.scatter([], [], color=style.color, marker=style.marker, label=style.label)
    ax.set(xscale="log", xlabel="CPU seconds per view (log scale; this process, all threads)", ylabel="mIoU (%)")
    ax.grid(True, which="both", alpha=0.3)
    fig.legend(*ax.get_legend_handles_labels(), loc="lower left", bbox_to_anchor=(0.655, 0.1), fontsize=8)
    key = [f"{i:>2}  {r['name']} ({inputs_name(r['inputs'])}): {r['miou']:.2f}%, {r['s_per_view']:.2f} CPU s"
           for i, r in enumerate(rows, 1)]
    fig.text(0.66, 0.84, "\n".join(key), va="top", ha="left", family="monospace", fontsize=8)
    what = "S-Ray's render settings" + (f" and {', '.join(others)}" if others else "")
    title = [f"Zero-shot accuracy against render time: {what}"] + textwrap.wrap(protocol, 150)
    fig.text(0.5, 0.98, "\n".join(title), va="top", ha="center", fontsize=8)
    return save_png(fig, path, dpi=120)
