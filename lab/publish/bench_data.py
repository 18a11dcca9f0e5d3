"""The benchmarks' stored tables as the publisher reads them; the one module of the lab's publisher that imports the
product's benchmark writer (``sray.platform.common.bench_doc``), so a generated page renders exactly as
``record`` writes it."""

from __future__ import annotations

from sray.platform.common.bench_doc import (  # noqa: F401  (re-exported for the publisher's other modules)
    DATA_FILE,
    INDEX_MARKER,
    Bench,
    TableRecord,
    device_slug,
    page_header,
    render_section,
    section_title,
)
from sray.platform.common.doc_blocks import markdown_table  # noqa: F401
