"""The Pareto front of benchmark rows: what no other row beats on both cost and score."""

from __future__ import annotations


def pareto(rows: list[dict], cost: str = "s_per_view", score: str = "miou") -> list[dict]:
    """Rows no other row beats on both ``cost`` (lower is better) and ``score`` (higher is better),
    cheapest first."""
    front, best = [], float("-inf")
    for r in sorted(rows, key=lambda r: (r[cost], -r[score])):
        if r[score] > best:
            front.append(r)
            best = r[score]
    return front
