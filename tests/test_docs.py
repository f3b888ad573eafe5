"""The documentation: the site builds without a warning, the docstring examples run, the figures page renders its file.

The build runs Sphinx as ``make docs`` does (``-W``: every warning an error)
on a copy of ``docs/`` in a temporary folder, with the gallery's scripts on
shortened records (``VEHID_DOCS_QUICK=1``) and a figures file written here,
so that what the generated page must show is known independently of any
benchmark run.
"""

from __future__ import annotations

import doctest
import importlib
import json
import os
import shutil
import subprocess
import sys
from html.parser import HTMLParser
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
PACKAGES = ("identification", "vehicle", "scenarios")

sys.path.insert(0, str(DOCS / "_ext"))
import benchmark_tables  # noqa: E402  (the extension lives with the docs, not in the package)


def _modules_with_examples() -> list[str]:
    names = []
    for package in PACKAGES:
        for path in sorted((ROOT / package).rglob("*.py")):
            if ">>>" in path.read_text(encoding="utf-8"):
                names.append("vehid." + ".".join(path.relative_to(ROOT).with_suffix("").parts))
    return names


@pytest.mark.parametrize("module_name", _modules_with_examples())
def test_docstring_examples_run(module_name):
    module = importlib.import_module(module_name)
    finder = doctest.DocTestFinder(exclude_empty=True)
    runner = doctest.DocTestRunner(optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE)
    tests = [test for test in finder.find(module, module_name) if test.examples]
    assert tests, f"{module_name} has '>>>' in its source but no docstring example was found"
    for test in tests:
        runner.run(test)
    failed, attempted = runner.summarize(verbose=False)
    assert failed == 0, f"{failed} of {attempted} docstring examples of {module_name} failed (doctest report above)"


def test_docstring_examples_are_found():
    # A search that found nothing would make the parametrised test above vanish, not fail.
    assert len(_modules_with_examples()) >= 5


# The figures renderer, on values whose rendering is known exactly.

def test_cell_text_rounds_to_four_figures_and_quotes_text():
    assert benchmark_tables.cell_text(1.234567) == "1.235"
    assert benchmark_tables.cell_text(12345.6) == "1.235e+04"
    assert benchmark_tables.cell_text(2.5e7) == "2.500e+07"
    assert benchmark_tables.cell_text(4e-5) == "4.000e-05"
    assert benchmark_tables.cell_text(0.0) == "0"
    assert benchmark_tables.cell_text(7) == "7"
    assert benchmark_tables.cell_text(True) == "yes"
    assert benchmark_tables.cell_text(None) == ""
    assert benchmark_tables.cell_text(float("nan")) == "n/a"
    assert benchmark_tables.cell_text("a *b* `c`") == "``a *b* `c```"
    assert benchmark_tables.cell_text([1, 2.5]) == "1, 2.5"


def test_a_mapping_of_rows_becomes_one_table_with_a_row_per_key():
    lines = benchmark_tables.render_value({"dryer": {"fit": 85.3, "order": 4}, "arm": {"fit": 96.4}}, "records", 1)
    text = "\n".join(lines)
    assert text.count(".. list-table::") == 1
    assert "     - fit\n     - order" in text
    assert "   * - ``dryer``\n     - 85.3\n     - 4" in text
    # A column a row lacks stays empty rather than shifting the row's cells.
    assert "   * - ``arm``\n     - 96.4\n     -  " in text


def test_nested_sections_get_headings_one_level_down():
    lines = benchmark_tables.render_value({"seconds": 1.5, "by_order": {"n2": {"r": 98.7}}}, "", 0)
    text = "\n".join(lines)
    assert "by order\n--------" in text
    assert "   * - ``seconds``\n     - 1.5" in text


def test_provenance_names_time_and_machine():
    sentence = benchmark_tables.provenance({"measured_at": "2026-11-26T10:00:00+0000",
                                            "machine": {"cpus": 2, "python": "3.11.7"}})
    assert sentence == "Measured 2026-11-26T10:00:00+0000 on a machine with cpus 2, python 3.11.7."


class _Text(HTMLParser):
    """The visible text of a page, and the images it shows."""

    def __init__(self):
        super().__init__()
        self.text: list[str] = []
        self.images: list[str] = []

    def handle_data(self, data):
        self.text.append(data)

    def handle_starttag(self, tag, attrs):
        if tag == "img":
            self.images.extend(value for name, value in attrs if name == "src")


def _page(path: Path) -> _Text:
    parser = _Text()
    parser.feed(path.read_text(encoding="utf-8"))
    return parser


FIGURES = {
    "iekf_linear": {
        "passes_per_second": 123.456789,
        "by_order": {"n2": {"seconds": 0.5, "fit_percent": 98.68}, "n4": {"seconds": 0.75, "fit_percent": 99.26}},
        "measured_at": "2026-11-26T10:00:00+0000",
        "machine": {"cpus": 2},
    },
    "read_records": {"rows": 1800000, "seconds": 1.4},
}


@pytest.fixture(scope="module")
def built_site(tmp_path_factory):
    """The site built from a copy of docs/ as ``make docs`` builds it, the gallery on shortened records."""
    work = tmp_path_factory.mktemp("docs")
    source = work / "docs"
    # What a build writes into docs/ is left out, so that the copy is what a fresh clone holds.
    generated = {"_build", "auto_examples", "generated", "sg_execution_times.rst"}
    written_api_pages = {"identification.rst", "vehicle.rst", "scenarios.rst", "command_line.rst"}

    def left_out(folder, names):
        pages = written_api_pages if Path(folder).name == "api" else set()
        return [name for name in names if name in generated or name in pages]

    shutil.copytree(DOCS, source, ignore=left_out)
    figures = work / "benchmarks.json"
    figures.write_text(json.dumps(FIGURES))
    environment = {**os.environ, "VEHID_DOCS_QUICK": "1", "VEHID_BENCHMARKS_JSON": str(figures),
                   "MPLBACKEND": "Agg"}
    html = work / "html"
    completed = subprocess.run(
        [sys.executable, "-m", "sphinx", "-W", "--keep-going", "-q", "-b", "html", "-d", str(work / "doctrees"),
         str(source), str(html)],
        cwd=work, env=environment, capture_output=True, text=True, timeout=900,
    )
    return completed, html


@pytest.mark.slow
def test_site_builds_without_a_warning(built_site):
    completed, html = built_site
    assert completed.returncode == 0, f"sphinx -W failed:\n{completed.stderr[-4000:]}"
    assert (html / "index.html").exists()


@pytest.mark.slow
def test_every_gallery_script_draws_a_figure(built_site):
    completed, html = built_site
    assert completed.returncode == 0, completed.stderr[-2000:]
    scripts = sorted(path.stem for path in (DOCS / "examples").glob("plot_*.py"))
    assert len(scripts) >= 4
    for script in scripts:
        page = html / "auto_examples" / f"{script}.html"
        assert page.exists(), f"no gallery page for {script}"
        figures = [src for src in _page(page).images if f"sphx_glr_{script}_" in src and "thumb" not in src]
        assert figures, f"the gallery page of {script} shows no figure"


@pytest.mark.slow
def test_api_reference_has_a_page_for_every_public_name(built_site):
    completed, html = built_site
    assert completed.returncode == 0, completed.stderr[-2000:]
    for package in ("vehid.identification", "vehid.vehicle", "vehid.scenarios"):
        for name in importlib.import_module(package).__all__:
            assert (html / "api" / "generated" / f"{package}.{name}.html").exists(), f"{package}.{name} has no page"


@pytest.mark.slow
def test_figures_page_shows_the_figures_file(built_site):
    completed, html = built_site
    assert completed.returncode == 0, completed.stderr[-2000:]
    text = " ".join(" ".join(_page(html / "benchmarks.html").text).split())
    assert "iekf linear" in text and "read records" in text
    assert "123.5" in text  # passes_per_second to four significant figures
    assert "98.68" in text and "99.26" in text and "1800000" in text
    assert "Measured 2026-11-26T10:00:00+0000" in text


@pytest.mark.slow
def test_command_line_reference_lists_every_command(built_site):
    completed, html = built_site
    assert completed.returncode == 0, completed.stderr[-2000:]
    text = " ".join(_page(html / "api" / "command_line.html").text)
    for command in ("vehid identify", "vehid simulate", "vehid study handling", "vehid report"):
        assert command in text
    assert "--validation" in text
