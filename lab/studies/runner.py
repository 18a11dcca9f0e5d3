"""Run a study on the engine ``sray sweep`` uses: one trial per arm and seed, resumable, tracked.

The stored results (``jobs/studies/results/<study>/``) are the study's memory: a trial whose result file exists
never runs again (an imported or transcribed one neither), so a study interrupted anywhere, or grown by an arm or a
seed, runs only its missing trials. The engine's own records (``<out>/<study>/study/trials/``) carry the rest: a
trial that errored runs again in the next launch, and an interrupted training job resumes from its checkpoint.
"""

from __future__ import annotations

import time
from functools import partial
from pathlib import Path

from sray.data_tools.synth.world import make_world
from sray.lab.studies.results import read_results
from sray.lab.studies.spec import ROOM_SPLITS, StudySpec
from sray.lab.studies.trial import study_trial, world_folder
from sray.platform.sweep.prepare import TRIAL_RESOURCES
from sray.platform.sweep.engine import missing, run_missing
from sray.platform.sweep.outcomes import TrialOutcome
from sray.platform.sweep.study import FINISHED, StudySettings, TrialRecord, read_record, trial_folder, write_record
from sray.platform.train.launcher import init_ray

STUDY_DIR = "study"
"""Sub-folder of a study's work folder holding the engine's trial records and Tune's state."""


def study_plan(spec: StudySpec) -> dict[str, dict[str, object]]:
    """Trial key -> point (``arm``, ``seed``) of every trial the study names, arms in file order."""
    return {key: {"arm": arm, "seed": seed} for key, (arm, seed) in spec.trial_keys().items()}


def missing_trials(spec: StudySpec) -> dict[str, dict[str, object]]:
    """The trials of the study without a stored result, in plan order."""
    stored = read_results(spec.results_dir)
    return {key: point for key, point in study_plan(spec).items() if key not in stored}


def make_worlds(spec: StudySpec, out: Path) -> list[Path]:
    """Generate (or verify) the shards of every world the study trains or scores on, under ``<out>/worlds/``, in
    the order first named: each arm's world, then the worlds of the evaluations (test splits, validation). Nothing
    is trained."""
    evaluated = [spec.evaluation_world(split) for split in spec.evaluations if split in ROOM_SPLITS]
    worlds = list(dict.fromkeys([*(spec.arm_world(arm) for arm in spec.arms.values()),
                                 *(w for w in evaluated if w is not None)]))
    return [make_world(world, world_folder(out, world), progress=True) for world in worlds]


def run_study_spec(spec: StudySpec, out: Path, tracking_uri: str, address: str | None = None,
                   max_minutes: float | None = None) -> list[TrialOutcome]:
    """Run every trial of ``spec`` without a stored result, one at a time (each trial's training takes its own Ray
    Train workers); none starts after ``max_minutes``. The outcome of each trial that had to run."""
    todo = missing_trials(spec)
    folder = Path(out) / spec.name
    settings = StudySettings(folder=folder / STUDY_DIR, metric="validation" if "validation" in spec.evaluations
                             else "zero_shot", mode="max", max_concurrent=1, trial_resources=TRIAL_RESOURCES,
                             start_by=time.time() + 60 * max_minutes if max_minutes else 0.0, reuse_actors=True,
                             label=f"study {spec.name}")
    for key in todo:  # a result file deleted to rerun its trial: the engine's record of it goes too
        record = read_record(trial_folder(settings.folder, key))
        if record.outcome == FINISHED:
            write_record(trial_folder(settings.folder, key), TrialRecord(launches=record.launches))
    if todo and missing(settings.folder, todo):
        init_ray(address)
    point_fn = partial(study_trial, spec_path=str(spec.path.resolve()), out=str(folder), tracking_uri=tracking_uri)
    return run_missing(todo, point_fn, settings)
