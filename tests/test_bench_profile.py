"""``sray bench profile`` at toy sizes: the profiler tables and the render levers it times."""

from __future__ import annotations

from pathlib import Path

import torch

from sray.jobs.bench.profile import run_profiles, write_profiles
from sray.platform.common.bench_doc import device_kind


def _rows(table: str) -> list[list[str]]:
    return [[c.strip() for c in line.split("|")[1:-1]] for line in table.splitlines() if line.startswith("| ")][1:]


def test_profiles_and_levers_are_written_and_the_kernels_agree(tmp_path: Path) -> None:
    """Every requested section is written once; the profile tables name operators (aten ones among them)
    with shares that sum to at most 100%; the four attention implementations agree to fp32 rounding; each chunk size of
    each implementation has a row."""
    sections = run_profiles(torch.device("cpu"), ("reference", "fast"), ("train", "render", "kernels", "chunks"),
                            quick=True)
    titles = [t for t, _, _ in sections]
    assert titles == ["Profile: training step, impl=reference", "Profile: whole-image render, impl=reference",
                      "Profile: training step, impl=fast", "Profile: whole-image render, impl=fast",
                      "Render lever: attention kernels at the render's shapes", "Render lever: rays per chunk"]
    for _, table, _ in sections[:4]:
        rows = _rows(table)
        assert rows and all(r[0].startswith("`") and r[0].endswith("`") and int(r[1]) >= 1 for r in rows)
        assert any(r[0].startswith("`aten::") for r in rows)
        assert 0 < sum(float(r[3].rstrip("%")) for r in rows) <= 100.05
    kernels = _rows(sections[4][1])
    assert len(kernels) == 10 and {r[0] for r in kernels} == {"intra-view", "cross-view"}
    assert all(float(r[5]) < 1e-5 for r in kernels)
    chunk_rows = [r for part in sections[5][1].split("\n\n") for r in _rows(part)]
    assert [(r[0], r[1]) for r in chunk_rows] == [("reference", "64"), ("reference", "16"), ("fast", "64"),
                                                  ("fast", "16")]
    doc = tmp_path / "benchmarks.md"
    write_profiles(sections, doc)
    text = doc.read_text()
    assert text.count(f"## Profiles ({device_kind()})\n") == 1 and all(text.count(f"### {t}\n") == 1 for t in titles)


def test_training_kernel_lever_times_forward_and_backward_of_the_flash_options_at_intra_view() -> None:
    """``train-kernels``: forward + backward rows; the intra-view stage skips the two implementations
    that store every score matrix at once, the cross-view stage keeps all five; all agree to fp32 rounding."""
    [(title, table, _)] = run_profiles(torch.device("cpu"), ("fast",), ("train-kernels",), quick=True)
    assert title.startswith("Training lever: attention kernels")
    rows = _rows(table)
    assert [r[0] for r in rows] == ["intra-view"] * 3 + ["cross-view"] * 5
    assert rows[2][2].startswith("matmul + softmax in cache-sized slices")
    assert all(float(r[3]) > 0 and float(r[5]) < 1e-5 for r in rows)


def test_attention_key_table_times_both_kernels_per_length_and_names_the_one_attention_uses() -> None:
    """``attention-keys``: forward and forward + backward per sample count; the last column is the
    dispatch rule's choice (8 keys: SDPA flash; 24: sliced in a render, SDPA with a gradient), and the
    ratio is the two timings'."""
    [(title, table, _)] = run_profiles(torch.device("cpu"), ("fast",), ("attention-keys",), quick=True)
    assert title.startswith("Attention kernel by key length")
    rows = _rows(table)
    assert [(r[0], r[1]) for r in rows] == [("8", "forward"), ("8", "forward + backward"),
                                            ("24", "forward"), ("24", "forward + backward")]
    assert [r[5] for r in rows] == ["SDPA flash"] * 2 + ["sliced", "SDPA flash"]
    for r in rows:
        flash, sliced, ratio = float(r[2]), float(r[3]), float(r[4])
        assert flash > 0 and sliced > 0 and abs(ratio - flash / sliced) <= 0.015 * ratio + 0.006
