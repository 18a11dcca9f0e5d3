"""How often Ray Train's controller polls its workers, on one machine.

The controller learns that a worker group has started, reported a checkpoint or finished only when it
polls the group, every ``RAY_TRAIN_HEALTH_CHECK_INTERVAL_S`` seconds (Ray's default 2 s; a missed poll
only counts against a worker after 10 minutes). A short job waits for those polls at its start, at
each report and at its end: a 6-step local job took 33.4 s with 2 s and 27.7 s with 0.5 s (two
alternating pairs, 2-core machine). On one machine a poll is a local call, so sray's local Ray and
local cluster poll every 0.5 s unless the user set the variable; clusters of many machines keep
Ray's default.
"""

from __future__ import annotations

TRAIN_POLL_ENV = {"RAY_TRAIN_HEALTH_CHECK_INTERVAL_S": "0.5"}
"""Environment of a driver on one machine; Ray Train passes the variable on to its controller."""
