"""The ``sray gpu-check`` stages in run order (kept apart so ``sray --help`` imports no torch)."""

STAGE_NAMES = ("environment", "tests", "precision", "training", "bench", "profile", "ray", "fleet")
