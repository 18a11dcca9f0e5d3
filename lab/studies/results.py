"""A study's stored results: one small JSON per trial, ``jobs/studies/results/<study>/<arm>--s<seed>.json``, in the
repository (the format all stored study results share: ``FORMAT``; mIoU and accuracies in percent, missing values
null, never invented).

```json
{"format": 1, "study": "hour-levers", "arm": "ema", "seed": 0, "recipe": "synth-cpu-hour",
 "overrides": {"optim.ema_decay": 0.998}, "budget": {"cpu_seconds": 3600, "steps": null},
 "trained": {"ray_steps": 4750, "cpu_seconds": 3595.2, "wall_seconds": 2100.0, "peak_memory_gib": 1.8},
 "metrics": {"zero_shot": {"miou": 56.96, "total_acc": 83.1, "class_avg_acc": 60.0, "per_class_iou": {"wall": 87.0},
                           "rooms": 4, "views": 16, "protocol": "..."}, "held_out": {...}, "validation": {...}},
 "machine": {"cpu_model": "...", "cores": 2, "device": "cpu", "ray_steps_per_cpu_second": null},
 "commit": "7734061", "source": "run"}
```

``source`` is ``run`` for a trial the runner made, ``imported: <file>@<commit>`` or
``transcribed: docs/benchmarks.md@<commit>`` for an older result brought in once.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from sray.data_tools.atomic import atomic_write_json

FORMAT = 1
KEYS = ("format", "study", "arm", "seed", "recipe", "overrides", "budget", "trained", "metrics", "machine", "commit",
        "source")
"""Every key of a stored result, in the order it is written."""
SOURCES = ("run", "imported: ", "transcribed: ")
"""How a ``source`` value begins."""


def trial_key(arm: str, seed: int) -> str:
    """``<arm>--s<seed>``: the trial's key and its result file's stem."""
    return f"{arm}--s{seed}"


def result_path(results_dir: Path, arm: str, seed: int) -> Path:
    """The stored result of (``arm``, ``seed``)."""
    return Path(results_dir) / f"{trial_key(arm, seed)}.json"


def check_result(result: dict[str, Any], where: str) -> dict[str, Any]:
    """``result`` when it has the format's keys and a known source; ValueError naming ``where`` and the key."""
    absent = [k for k in KEYS if k not in result]
    if absent:
        raise ValueError(f"{where}: stored result lacks {absent[0]!r}; every result has {', '.join(KEYS)}")
    if result["format"] != FORMAT:
        raise ValueError(f"{where}: format {result['format']!r}; this sray reads format {FORMAT}")
    if not str(result["source"]).startswith(SOURCES):
        raise ValueError(f"{where}: source {result['source']!r}; write run, 'imported: FILE@COMMIT' or "
                         "'transcribed: FILE@COMMIT'")
    return result


def write_result(results_dir: Path, result: dict[str, Any]) -> Path:
    """Store ``result`` (checked) atomically under its arm and seed; returns the file."""
    path = result_path(results_dir, result["arm"], int(result["seed"]))
    check_result(result, str(path))
    atomic_write_json(path, {k: result[k] for k in KEYS})
    return path


def read_results(results_dir: Path) -> dict[str, dict[str, Any]]:
    """Every stored result of a study (``<arm>--s<seed>.json``), by trial key in sorted order (empty for a folder not
    yet made); other files in the folder, such as a study's measured step costs, are not trials."""
    folder = Path(results_dir)
    if not folder.is_dir():
        return {}
    results = {}
    for path in sorted(folder.glob("*--s*.json")):  # other files there are a study's side measurements
        try:
            result = json.loads(path.read_text())
        except json.JSONDecodeError as e:
            raise ValueError(f"{path}: not readable as JSON ({e.msg}); restore it from git or delete it to rerun "
                             "the trial") from None
        check_result(result, str(path))
        if path.stem != trial_key(result["arm"], int(result["seed"])):
            raise ValueError(f"{path}: holds arm {result['arm']!r} seed {result['seed']}; rename it "
                             f"{trial_key(result['arm'], int(result['seed']))}.json")
        results[path.stem] = result
    return results


def metric(result: dict[str, Any], split: str, name: str = "miou") -> float | None:
    """``result``'s ``name`` on ``split`` (percent; a dotted split such as ``fleet.sray`` names a nested block), None
    when it was not measured."""
    block = result["metrics"]
    for key in split.split("."):
        block = block.get(key) or {}
    value = block.get(name)
    return None if value is None else float(value)
