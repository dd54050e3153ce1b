"""The README and docs/: the Python example runs as printed, and every relative link finds its file."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).parents[1]
PAGES = [
    *(REPO / name for name in ("README.md", "BENCHMARKS.md", "RELIABILITY.md", "REPRODUCTION.md")),
    *sorted((REPO / "docs").glob("*.md")),
]
# Pages for users that say what holds today: no issue or session numbers (the history keeps those).
USER_PAGES = ["BENCHMARKS.md", "RELIABILITY.md", "REPRODUCTION.md"] + [
    f"docs/{name}.md" for name in ("comparison", "conventions", "decisions", "evaluation", "g2o", "install", "overview")
]
LINK = re.compile(r"\]\(([^)\s]+)\)")


def test_readme_python_examples_run_as_printed(tmp_path):
    readme = (REPO / "README.md").read_text(encoding="utf-8")
    snippet, online = re.findall(r"```python\n(.*?)```", readme, flags=re.DOTALL)
    for example in (snippet, online):
        assert len(example.strip().splitlines()) <= 12  # ten lines, not a reference
    done = subprocess.run([sys.executable, "-c", online], capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    iterations, *_ = done.stdout.split()
    assert int(iterations) > 0 and done.stdout.rstrip().endswith("[]")  # solved; the true loop stays
    (tmp_path / "datasets").symlink_to(REPO / "datasets")  # its paths are relative to the checkout
    run = subprocess.run(
        [sys.executable, "-c", snippet], cwd=tmp_path, capture_output=True, text=True, timeout=300
    )
    assert run.returncode == 0, run.stderr
    assert run.stdout.startswith("Result(method='egnc'")
    assert (tmp_path / "solved.g2o").is_file()


@pytest.mark.parametrize("page", PAGES, ids=lambda path: path.name)
def test_relative_links_point_at_files(page):
    text = page.read_text(encoding="utf-8")
    for target in LINK.findall(text):
        if re.match(r"[a-z]+:", target) or target.startswith("#"):
            continue  # a URL, or an anchor on the same page
        file, _, anchor = target.partition("#")
        path = (page.parent / file).resolve()
        assert path.exists(), f"{page.name}: {target}"
        if anchor and path.suffix == ".md":
            assert anchor in anchors(path), f"{page.name}: {target}: no such heading"


def anchors(page: Path) -> set[str]:
    """GitHub's anchors of a Markdown page's headings: lower case, punctuation dropped, spaces to hyphens."""
    headings = re.findall(r"(?m)^#+ (.+)$", page.read_text(encoding="utf-8"))
    return {re.sub(r"[^\w\- ]", "", heading.strip().lower()).replace(" ", "-") for heading in headings}


def test_readme_stays_a_newcomer_page():
    lines = (REPO / "README.md").read_text(encoding="utf-8").splitlines()
    assert len(lines) <= 160
    assert "## Robust default and initial guesses" in lines


def test_benchmarks_is_one_page_of_current_figures():
    lines = (REPO / "BENCHMARKS.md").read_text(encoding="utf-8").splitlines()
    assert len(lines) <= 400


@pytest.mark.parametrize("name", USER_PAGES)
def test_user_pages_carry_no_issue_or_session_numbers(name):
    text = (REPO / name).read_text(encoding="utf-8")
    found = re.findall(r"(?i)\bissues?[ -]#?\d+|\b\w+(?:-\w+)? session\b", text)
    assert not found, f"{name}: {found}"
