"""The documentation site builds without a warning, stands on its own in a clone (no
page points outside the repository to the team's shared folder), and the README stays
short."""

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
OUTSIDE = ("../shared", "shared/docs", "shared/data")
README_MAX_LINES = 200


def _pages() -> list[Path]:
    return [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md"))]


@pytest.mark.slow
def test_the_site_builds_strictly(tmp_path):
    """mkdocs, mkdocs-material and mkdocstrings are in the test extra: without them this
    fails rather than skips, so that CI cannot pass without building the site."""
    done = subprocess.run(
        [sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(tmp_path)],
        cwd=ROOT,  # the snippets (the changelog) are found from the repository root
        capture_output=True,
        text=True,
        env={**os.environ, "NO_MKDOCS_2_WARNING": "1"},
    )
    warnings = [line for line in done.stderr.splitlines() if "WARNING" in line or "ERROR" in line]
    assert done.returncode == 0, "mkdocs build --strict failed:\n" + "\n".join(
        warnings or done.stderr.splitlines()[-20:]
    )
    assert (tmp_path / "index.html").is_file() and (tmp_path / "api" / "index.html").is_file()


def test_no_page_points_to_the_shared_folder():
    found = [
        f"{page.relative_to(ROOT)}:{number}: {line.strip()}"
        for page in _pages()
        for number, line in enumerate(page.read_text().splitlines(), start=1)
        if any(outside in line for outside in OUTSIDE)
    ]
    assert not found, "pages pointing outside the repository:\n" + "\n".join(found)


def test_no_table_cell_holds_a_pipe_in_code():
    """GitHub splits a table row at a pipe even inside code, MkDocs does not, and an
    escaped pipe shows its backslash in MkDocs: tables say {a,b} instead."""
    found = [
        f"{page.relative_to(ROOT)}:{number}: {span}"
        for page in _pages()
        for number, line in enumerate(page.read_text().splitlines(), start=1)
        if line.startswith("|")
        for span in re.findall(r"`([^`]*)`", line)
        if "|" in span
    ]
    assert not found, "pipes inside code in tables:\n" + "\n".join(found)


def test_the_readme_is_at_most_200_lines():
    lines = len((ROOT / "README.md").read_text().splitlines())
    assert lines <= README_MAX_LINES, f"README.md has {lines} lines (at most {README_MAX_LINES})"
