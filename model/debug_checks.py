"""Opt-in checks that read tensor values (``far >= near`` on every ray, label ids in range), so sync the device: on
only with ``SRAY_DEBUG_CHECKS=1`` (read at import); the loader and scene checks validate those values."""

from __future__ import annotations

import os

ENV_VAR = "SRAY_DEBUG_CHECKS"
"""Set to ``1`` to turn the value checks on (e.g. while debugging a new dataset reader)."""

ENABLED = os.environ.get(ENV_VAR, "") == "1"
"""Whether value checks run in this process (read at call time, so tests may patch it)."""
