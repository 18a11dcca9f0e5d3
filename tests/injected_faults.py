"""Turning sray's fault hook (``SRAY_FAULTS``, read in ``sray.platform.common.fault_hook``) on for a block."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager

import pytest

from sray.platform.common.fault_hook import ENV_VAR, parse_faults


@contextmanager
def injected_faults(spec: str) -> Iterator[None]:
    """Set ``SRAY_FAULTS=spec`` (validated first) inside the block; the previous value comes back after."""
    parse_faults(spec)
    with pytest.MonkeyPatch.context() as patch:
        patch.setenv(ENV_VAR, spec)
        yield
