"""``sray bench model`` machinery: analytic FLOP counts and the two tables in quick mode."""

from __future__ import annotations

import pytest
import torch

from sray.jobs.bench.model_cost import _row_key, _sizes, run_model_benchmark
from sray.jobs.bench.probes import attention_flops


def _analytic_forward_flops(variant: str, r: int, m: int, n: int, c: int, depth_freqs: int = 6) -> int:
    """Matmul FLOPs: 8 C^2 per token per block (q, k, v, output projections) + 4 L^2 C per sequence,
    plus the depth embedding (a (1 + 2F) -> C linear per sample) for the variants that add it."""
    tokens = r * m * n
    position = 2 * (1 + 2 * depth_freqs) * c * r * n
    intra = 8 * c * c * tokens + 4 * n * n * c * r * m
    cross = 8 * c * c * tokens + 4 * m * m * c * r * n
    dense = 8 * c * c * tokens + 4 * (m * n) ** 2 * c * r
    return {"full": position + intra + cross, "intra": position + intra, "cross": cross,
            "dense": position + dense}[variant]


@pytest.mark.parametrize("variant", ["full", "intra", "cross", "dense"])
def test_counted_flops_match_the_analytic_count(variant: str) -> None:
    sizes = {"rays": 64, "views": 3, "samples": 6, "channels": 16}
    got = attention_flops(variant, sizes, 4, torch.device("cpu"), backward=False)
    assert got == _analytic_forward_flops(variant, 64, 3, 6, 16)


def test_paper_size_flop_ratio_meets_the_target() -> None:
    paper = {"rays": 1024, "views": 8, "samples": 64, "channels": 32}
    full, dense = (_analytic_forward_flops(v, 1024, 8, 64, 32) for v in ("full", "dense"))
    assert attention_flops("full", paper, 2, torch.device("cpu"), backward=False) == full
    assert full / dense <= 0.55


def test_quick_benchmark_produces_both_tables() -> None:
    sections = run_model_benchmark(device="cpu", quick=True)
    assert len(sections) == 2
    (t1, table1, notes1), (t2, table2, _) = sections
    rows = {line.split("|")[1].strip(): line for line in table1.splitlines()[2:]}
    assert set(rows) == {"full", "intra", "cross", "dense"}
    dense_cells = [c.strip() for c in rows["dense"].split("|")[1:-1]]
    assert dense_cells[3] == "1.000" and dense_cells[6] == "1.000"
    for line in rows.values():
        cells = [c.strip() for c in line.split("|")[1:-1]]
        assert all(float(x) >= 0 for x in cells[1:])
    assert "target <= 0.55" in notes1
    assert "tiny" in table2 and "fp32" in table2
    ref_cells, fast_cells = ([c.strip() for c in line.split("|")[1:-1]] for line in table2.splitlines()[2:4])
    assert (ref_cells[2], fast_cells[2]) == ("16", "4")  # the reference in one piece, the fast row in pieces of 4
    assert (ref_cells[7], fast_cells[7]) == ("reference", "fast")
    assert float(fast_cells[9]) > 0 and float(fast_cells[10]) > 0 and float(fast_cells[12]) > 0
    assert ref_cells[14] == "-" and float(fast_cells[14].rstrip("x")) > 0  # fast vs reference of the same run
    # the unoptimised default (reference, union, glibc) is the same row here: the two ratios agree
    assert ref_cells[15] == "-" and fast_cells[15] == fast_cells[14]


def test_every_gpu_row_is_measured_beside_its_reference_path() -> None:
    """On CUDA each precision's fast rows (compiled or not) find a reference row of the same precision,
    samples and rays in the same run, so the table's 'vs reference' column is never empty there."""
    rows = [dict(spec, device="cuda") for spec in _sizes(torch.device("cuda"), quick=False).steps]
    keys = {_row_key(spec) for spec in rows}
    fast = [k for k in keys if k[2] == "fast"]
    assert {k[1] for k in fast} == {"fp32", "bf16", "fp16"} and any(k[6] and k[1] == "bf16" for k in fast)
    for name, dtype, _, alloc, fine, _, _ in fast:
        assert (name, dtype, "reference", alloc, fine, 1024, False) in keys


def test_the_official_code_table_reads_a_same_run_side_by_side(tmp_path) -> None:
    """``--official-side-by-side``: medians over the timed steps (each process's first is its warm-up) and every
    ratio against sray's default of the same file, never a stored constant."""
    import json

    from sray.jobs.bench.model_cost import official_side_by_side

    def runs(*steps: list[float], gib: float) -> list[dict]:
        return [{"times": [99.0, *s], "rss_bytes": gib * 2**30, "torch": "2.x", "threads": 2} for s in steps]

    path = tmp_path / "results.json"
    path.write_text(json.dumps({"official, THP_MEM_ALLOC_ENABLE=1": runs([13.0, 14.0], [13.5, 13.5], gib=11.0),
                                "sray default (no THP)": runs([4.0, 4.1], [3.9, 4.0], gib=2.0)}))
    title, table, notes = official_side_by_side(path)
    rows = {line.split(" | ")[0]: line.split(" | ") for line in table.splitlines()[2:]}
    official, sray = rows["official, THP_MEM_ALLOC_ENABLE=1"], rows["sray default (no THP)"]
    assert official[1] == "13.50" and sray[1] == "4.00" and sray[5:] == ["1.00x", "1.00x"]
    assert official[5:] == ["3.38x", "5.50x"] and "99" not in official[2]
    assert "same run" in title and "official_side_by_side/run.py" in notes
