"""Every published number regenerates: each generated block of README.md and docs/**/*.md (and each benchmark and
study page)
equals what ``python -m sray.lab.publish`` renders from the stored data it names, and no measured figure stands in
hand-written prose. Proven to fail: a README figure edited by hand, inside a block or outside one, is caught."""

from __future__ import annotations

import re
import shutil
from pathlib import Path

import pytest
from number_scan import docstring_figures, hand_written_lines, measured_figures

from sray.lab.publish.__main__ import main as publish_main
from sray.lab.publish.blocks import BlockError, blocks, fill
from sray.lab.publish.figures import CARDS_DATA, H100_REPORT, H200_REPORT, RENDERERS
from sray.platform.common import bench_doc
from sray.lab.publish.pages import render_page, slugs
from sray.lab.publish.publish import documents, publish, published
from sray.lab.publish.results import RESULTS, mean_sd

REPO = Path(__file__).resolve().parents[1]
DECIMAL = re.compile(r"\d+\.\d+")
SCANNED = [REPO / "README.md", REPO / "CONTRIBUTING.md", *sorted((REPO / "docs").rglob("*.md"))]

ALLOWED = {
    ("docs/data.md", "±3"): "the generator's colour-temperature jitter per lamp (a specification of the procedural "
                           "scenes, data_tools/synth/lighting.py)",
    ("docs/fleet.md", "5%"): "`transfer.tolerance`, a setting's value",
    ("docs/gpu.md", "30 views/s"): "the GPU check's target, a requirement rather than a measurement",
    ("docs/cluster.md", "64 MB"): "Docker's default /dev/shm size, a documented default",
    ("docs/cluster.md", "0.5 s"): "how often a job polls its workers, a setting",
    ("docs/training.md", "2 MiB"): "PyTorch's huge-page threshold, a documented constant",
    ("docs/training.md", "64 MiB"): "the size of the example tensor in the huge-page explanation",
}
"""(file, figure) -> why it is a specification, not a measurement. Kept short: a measured figure belongs in a
generated block."""


def _stale(repo: Path) -> list[str]:
    return [str(p.relative_to(repo)) for p, text in published(repo).items() if not p.exists() or p.read_text() != text]


def test_every_generated_block_and_page_matches_its_stored_data() -> None:
    """Re-render every generated block, benchmark page and study page from the stored data; each equals the file."""
    stale = _stale(REPO)
    assert not stale, f"out of date with their stored data: {stale}; run `python -m sray.lab.publish`"


def test_the_readme_publishes_its_headline_figures() -> None:
    """The README carries the recipe cards, the shipped recipe's headline, the GPU figures and the demo's time as
    generated blocks (an author cannot drop one silently)."""
    names = {b.name for b in blocks((REPO / "README.md").read_text(), "README.md")}
    assert {"recipe-cards", "hour-recipe", "gpu-training", "demo-time"} <= names


def test_no_measured_figure_outside_a_generated_block() -> None:
    """README, CONTRIBUTING and docs/: hand-written lines hold no measured figure but the allowed specifications; the
    Reading of a generated benchmark or study page quotes only numbers its own generated part shows."""
    found = []
    pages = {REPO / "docs" / "benchmarks" / f"{slug}.md" for slug in slugs(REPO / "docs")}
    pages |= {REPO / "docs" / "studies" / f"{spec.stem}.md" for spec in (REPO / "jobs" / "studies").glob("*.yaml")}
    for path in SCANNED:
        rel, text = str(path.relative_to(REPO)), path.read_text()
        if path in pages:  # a generated page: its Reading may quote only figures the page's generated part shows
            generated = text.split("\n## Reading\n")[0]
            found += [f"{rel}:{number}: {n!r} is not in the page's generated tables"
                      for number, line in hand_written_lines(text, generated_page=True)
                      for n in DECIMAL.findall(line) if n not in generated]
            continue
        for number, line in hand_written_lines(text):
            found += [f"{rel}:{number}: {f!r} in {line.strip()[:100]!r}" for f in measured_figures(line)
                      if (rel, f) not in ALLOWED]
    assert not found, "measured figures outside generated blocks (store them and publish a block):\n" + "\n".join(found)


def test_recipe_docstrings_hold_no_measured_figure() -> None:
    """The recipes say what a setting does and why in words and point at the studies; their figures are published."""
    text = (REPO / "platform" / "config" / "recipes.py").read_text()
    found = [f for line in text.splitlines() for f in measured_figures(line)]
    assert not found, f"platform/config/recipes.py: measured figures {found}; link the study instead"


PRODUCT = ("model", "data_tools", "platform", "jobs", "sray")
SPECIFIED = {
    ("model/sliced_attention.py", "4 MiB"): "a slice's size by design (elements per slice times 4 bytes)",
    ("model/sliced_attention.py", "32 MiB"): "the L3 cache size of the CPU it was sized for, a hardware specification",
    ("jobs/gpu_bundle/build.py", "64 MiB"): "what one GPU call may carry, a limit of the device service",
}
"""(file, figure) in a product docstring -> why it is a specification, not a measurement."""


def test_product_docstrings_hold_no_measured_figure() -> None:
    """Docstrings say what a setting does and why in words and link the study or page holding the numbers."""
    found = sorted((str(path.relative_to(REPO)), line, figure) for folder in PRODUCT
                   for path in (REPO / folder).rglob("*.py") for line, figure in docstring_figures(path.read_text())
                   if (str(path.relative_to(REPO)), figure) not in SPECIFIED)
    assert not found, f"measured figures in docstrings (file, line, figure): {found}; link the stored result instead"
    assert all(figure in (REPO / file).read_text() for file, figure in SPECIFIED), "a stale SPECIFIED entry"
    assert docstring_figures('"""A step takes 0.31 s."""\nX = 1\n"""It scores 53.94% zero-shot."""') == [
        (1, "0.31 s"), (3, "53.94%")]


def test_the_allow_list_is_used() -> None:
    """Every allowed figure still appears in its file (a stale entry would hide nothing and mislead)."""
    unused = [key for key in ALLOWED if key[1] not in (REPO / key[0]).read_text()]
    assert not unused


def test_the_scan_sees_measured_figures_and_passes_specifications() -> None:
    """Known measured figures are caught, specifications and settings are not."""
    for prose in ["scores 53.94% zero-shot", "a spread of ± 2", "14,875 rays/s in bf16", "0.43 CPU s / view",
                  "peak 1.8 GiB", "the demo takes 11 minutes", "1.55x faster", "holds 80% of its clean mIoU",
                  "steps in 0.477 s"]:
        assert measured_figures(prose), prose
    for prose in ["320x240 images, 8 source views", "a budget of 7200 CPU seconds", "30 % of rooms are L-shaped",
                  "64+64 samples", "`optim.steps=600`", "a 60 s finetune"]:
        assert not measured_figures(prose), prose


def _copy_inputs(tmp: Path) -> Path:
    """A repository holding the README and exactly the stored data its blocks read."""
    repo = tmp / "repo"
    (repo / "docs").mkdir(parents=True)
    shutil.copy(REPO / "README.md", repo / "README.md")
    shutil.copytree(REPO / RESULTS, repo / RESULTS)
    for data in (CARDS_DATA, H100_REPORT, H200_REPORT):
        (repo / data).parent.mkdir(parents=True, exist_ok=True)
        shutil.copy(REPO / data, repo / data)
        page = data.parent.parent.with_suffix(".md")  # the benchmark's generated page, rendered from that data
        shutil.copy(REPO / page, repo / page)
    return repo


def test_a_readme_figure_edited_by_hand_fails(tmp_path: Path) -> None:
    """On a copy: the untouched README passes; editing the headline inside its block makes it stale (and publish
    restores it); writing a figure into hand-written prose is caught by the scan."""
    repo = _copy_inputs(tmp_path)
    readme = repo / "README.md"
    assert _stale(repo) == []
    original = readme.read_text()
    assert "**53.94 ± 4.14%**" in original  # the headline as the stored seeds give it
    readme.write_text(original.replace("**53.94 ± 4.14%**", "**55.94 ± 4.14%**"))
    assert _stale(repo) == ["README.md"]
    assert publish(repo) == [readme] and readme.read_text() == original
    readme.write_text(original.replace("## Layout\n", "## Layout\n\nThe recipe scores 57.10% zero-shot.\n"))
    assert _stale(repo) == []  # outside every block: only the scan can see it
    lines = hand_written_lines(readme.read_text())
    assert [f for _, line in lines for f in measured_figures(line)] == ["57.10%"]


def test_a_page_renders_as_the_benchmark_wrote_it(tmp_path: Path, monkeypatch) -> None:
    """``sray bench`` writing through the index and the publisher rendering the page from the stored data agree
    byte for byte, so a rerun of a benchmark never leaves its page out of date."""
    monkeypatch.setattr(bench_doc, "describe_machine", lambda: {"cpu_model": "X", "cores": 2, "device": "cpu",
                                                                 "ray_steps_per_cpu_second": 1.0})
    docs = tmp_path / "docs"
    docs.mkdir()
    (docs / "benchmarks.md").write_text(f"# Benchmarks\n\n{bench_doc.INDEX_MARKER}\n")
    bench = bench_doc.Bench("loader", "Shard loader")
    bench_doc.record(bench, "Throughput", "| workers | samples/s |\n|---:|---:|\n| 0 | 1 |", docs / "benchmarks.md",
                     "![c](benchmarks/loader/cpu-only/c.png)")
    bench_doc.record(bench, "Bytes", "| view | bytes |\n|---|---:|\n| a | 2 |", docs / "benchmarks.md")
    assert render_page(docs, "loader") == (docs / "benchmarks" / "loader.md").read_text()


def test_headline_statistics_are_mean_and_sample_sd() -> None:
    """The spread shown is the sample standard deviation, checked on a hand-computed case."""
    mean, sd = mean_sd([53.85, 58.13, 49.85])
    assert mean == pytest.approx(53.943333) and sd == pytest.approx(4.1408, abs=1e-4)
    assert mean_sd([1.0]) == (1.0, None)


def test_blocks_refuse_unpaired_markers_and_keep_the_rest() -> None:
    """A block without its closing line is refused naming the file; filling changes only the blocks' bodies."""
    with pytest.raises(BlockError, match="x.md.*demo-time"):
        blocks("a\n<!-- published: demo-time -->\nold\n", "x.md")
    text = "head\n<!-- published: a -->\nold\n<!-- /published: a -->\ntail 1.5%\n"
    assert fill(text, lambda name: f"new {name}", "x.md") == (
        "head\n<!-- published: a -->\nnew a\n<!-- /published: a -->\ntail 1.5%\n")


def test_a_bad_stored_result_or_block_stops_the_publisher_naming_it(tmp_path: Path, capsys) -> None:
    """A trial without the figure a block reads, or a block no renderer knows, stops ``python -m sray.lab.publish``
    with exit 2 and the file and field (or block) named; nothing is written."""
    repo = _copy_inputs(tmp_path)
    trial = repo / RESULTS / "hour-recipe" / "hour-intra-uncapped--s1.json"
    trial.write_text(trial.read_text().replace('"held_out"', '"held_out_views"'))
    before = (repo / "README.md").read_text()
    assert publish_main(["--repo", str(repo)]) == 2
    assert "hour-intra-uncapped--s1.json: no field metrics.held_out.miou" in capsys.readouterr().err
    shutil.copy(REPO / RESULTS / "hour-recipe" / "hour-intra-uncapped--s1.json", trial)
    (repo / "README.md").write_text(before + "\n<!-- published: nobody -->\n<!-- /published: nobody -->\n")
    assert publish_main(["--repo", str(repo), "--check"]) == 2
    assert "README.md: no renderer named 'nobody'" in capsys.readouterr().err
    assert (repo / "README.md").read_text().startswith(before)


def test_every_renderer_fills_a_block() -> None:
    """No renderer is dead code: each fills a block of the README or docs."""
    used = {b.name for path in documents(REPO) for b in blocks(path.read_text(), str(path))}
    assert set(RENDERERS) <= used
