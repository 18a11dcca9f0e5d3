"""Opt-in value checks that need a device -> host sync, off on the hot path by default.

Shape and dtype checks cost nothing and always run. Checks that read tensor VALUES (``far >= near``
on every ray, label ids inside the class range) force the host to wait for the device; on a GPU
they idle it several times per training step. They run only when the environment variable
``SRAY_DEBUG_CHECKS`` is ``1`` (read once per process, at import). The values they guard are
validated once per batch where they are made instead (the loader, the scenes' checks).
"""

from __future__ import annotations

import os

ENV_VAR = "SRAY_DEBUG_CHECKS"
"""Set to ``1`` to turn the value checks on (e.g. while debugging a new dataset reader)."""

ENABLED = os.environ.get(ENV_VAR, "") == "1"
"""Whether value checks run in this process."""


def value_checks_enabled() -> bool:
    """True when ``SRAY_DEBUG_CHECKS=1``: run the checks that read tensor values."""
    return ENABLED
