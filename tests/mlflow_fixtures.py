"""Fresh MLflow SQLite stores for tests, without paying for the schema each time.

Creating a new store runs MLflow's migrations (3-7 s on the 2-core CI machine); copying a store
that already has the schema takes milliseconds. The first use in a session builds a template
under pytest's session temp folder; every test then gets its own copy. Use from a test module::

    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from mlflow_fixtures import mlflow_uri  # noqa: F401  (pytest fixture, used by name)
"""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest


@pytest.fixture(scope="session")
def mlflow_template(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Path of an empty SQLite store that already holds MLflow's schema (built once per session)."""
    from sray.platform.tracking.runs import ensure_store

    # A fixed path, not mktemp: every module importing this fixture gets its own session-scoped copy
    # of it, and they must all find the one template.
    db = tmp_path_factory.getbasetemp() / "mlflow-template" / "mlflow.db"
    if not db.exists():
        ensure_store(f"sqlite:///{db}")
    return db


@pytest.fixture
def mlflow_uri(mlflow_template: Path, tmp_path: Path) -> str:
    """``sqlite:///<tmp_path>/mlflow.db``: a private, ready store (artifacts go beside it)."""
    db = tmp_path / "mlflow.db"
    shutil.copyfile(mlflow_template, db)
    return f"sqlite:///{db}"
