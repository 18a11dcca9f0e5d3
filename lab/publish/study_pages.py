"""The studies' generated pages, ``docs/studies/<study>.md``, as the publisher checks and writes them: each rendered by
the study page writer (:mod:`sray.lab.studies.page`) from its spec file and stored trials, keeping its Reading."""

from __future__ import annotations

from pathlib import Path

from sray.lab.studies.page import page_path, reading_of, render_page
from sray.lab.studies.results import read_results
from sray.lab.studies.spec import StudySpec, load_study

SPECS = Path("jobs/studies")
"""The study files' folder, relative to the repository."""


def specs(repo: Path) -> list[StudySpec]:
    """Every study file of the repository."""
    return [load_study(path) for path in sorted((Path(repo) / SPECS).glob("*.yaml"))]


def expected_page(spec: StudySpec, docs: Path) -> tuple[Path, str]:
    """(page, its text) as ``sray lab study --page`` writes it; the chart is linked when it is there (the publisher
    writes the page, ``sray lab study --page`` also draws the chart)."""
    page = page_path(spec, docs)
    chart = f"{spec.name}/miou.png"
    return page, render_page(spec, read_results(spec.results_dir), reading_of(page),
                             chart if (page.parent / chart).exists() else None)

