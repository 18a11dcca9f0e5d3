"""Rank-0 progress bars that render cleanly whether or not the code runs inside a Ray worker."""

from __future__ import annotations

from typing import Any


class _NoBar:
    """The progress bar of ranks other than 0: does nothing."""

    def update(self, n: int = 1) -> None:
        """Ignore progress."""

    def set_postfix(self, **values: Any) -> None:
        """Ignore status text."""

    def close(self) -> None:
        """Nothing to close."""


class _RayBar:
    """Ray's driver-rendered bar (``ray.experimental.tqdm_ray``): ETA and rate, one line per bar."""

    def __init__(self, total: int, initial: int, desc: str) -> None:
        from ray.experimental import tqdm_ray

        self.desc = desc
        self._bar = tqdm_ray.tqdm(total=total, desc=desc, unit="step")
        if initial:
            self._bar.update(initial)

    def update(self, n: int = 1) -> None:
        """Advance by ``n`` steps."""
        self._bar.update(n)

    def set_postfix(self, **values: Any) -> None:
        """Show ``key=value`` pairs after the description."""
        self._bar.set_description(f"{self.desc} " + " ".join(f"{k}={v}" for k, v in values.items()))

    def close(self) -> None:
        """Finish the bar."""
        self._bar.close()


def make_progress(enabled: bool, total: int, initial: int = 0, desc: str = "") -> Any:
    """A bar with ETA on rank 0 (``enabled``), a silent stand-in elsewhere.

    Inside a Ray worker the bar is drawn by the driver (``tqdm_ray``); elsewhere it is plain tqdm.
    """
    if not enabled:
        return _NoBar()
    import ray

    if ray.is_initialized() and ray.get_runtime_context().worker.mode == ray.WORKER_MODE:
        return _RayBar(total, initial, desc)
    from tqdm import tqdm

    return tqdm(total=total, initial=initial, desc=desc, unit="step", mininterval=1.0)
