"""``make bench`` writes its tables into docs/benchmarks.md, between the page's markers."""
import importlib.util
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def bench():
    spec = importlib.util.spec_from_file_location("bench_run", REPO / "bench" / "run.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_the_docs_page_has_one_results_block(bench):
    text = bench.DOCS_PAGE.read_text(encoding="utf-8")
    assert bench.DOCS_PAGE == REPO / "docs" / "benchmarks.md"
    assert text.count(bench.RESULTS_BEGIN) == 1 and text.count(bench.RESULTS_END) == 1
    assert text.index(bench.RESULTS_BEGIN) < text.index(bench.RESULTS_END)


def test_a_run_replaces_the_block_and_keeps_the_hand_written_rest(bench, tmp_path):
    page = tmp_path / "benchmarks.md"
    page.write_text(bench.DOCS_PAGE.read_text(encoding="utf-8"), encoding="utf-8")
    before = page.read_text(encoding="utf-8")
    first = "| case | figure | value |\n|---|---|---|\n| evaluate | seconds | 1.5 |"
    bench.write_results_page(page, first, "2026-11-27, commit abc1234, x86_64, 2 cores")
    bench.write_results_page(page, first.replace("1.5", "2.5"), "2026-11-28, commit def5678")
    after = page.read_text(encoding="utf-8")
    assert "| evaluate | seconds | 2.5 |" in after and "1.5 |" not in after
    assert "Last whole run: 2026-11-28, commit def5678." in after
    assert "abc1234" not in after
    head = before.split(bench.RESULTS_BEGIN)[0]
    tail = before.split(bench.RESULTS_END)[1]
    assert after.startswith(head) and after.endswith(tail)
    assert list(tmp_path.iterdir()) == [page]  # the temporary file is renamed, not left


def test_a_page_without_its_markers_is_refused_untouched(bench, tmp_path):
    page = tmp_path / "benchmarks.md"
    page.write_text("# Benchmarks\n", encoding="utf-8")
    with pytest.raises(ValueError, match="BEGIN make bench results"):
        bench.write_results_page(page, "| a |", "today")
    assert page.read_text(encoding="utf-8") == "# Benchmarks\n"
