"""The documentation site: it builds with ``mkdocs build --strict`` (a broken link, a
missing image, a page outside the navigation or a docstring the API reference cannot
render fails), every Python snippet of its pages runs, and the README stays short. The
pages' shell commands run in tests/test_readme.py and tests/test_analysis_report.py
(``tests/readme_commands.py`` collects them from the README and every page)."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest
from readme_commands import PAGES, README, REPO, environment

pytestmark = pytest.mark.slow

README_LINES = 150


def python_snippets() -> list[tuple[str, str]]:
    """(page:line, code) of every fenced ``python`` block of the pages."""
    found = []
    for page in PAGES:
        text = page.read_text()
        for match in re.finditer(r"^```python[^\n]*\n(.*?)^```", text, re.S | re.M):
            line = text.count("\n", 0, match.start()) + 1
            found.append((f"{page.relative_to(REPO)}:{line}", match.group(1)))
    return found


def test_the_site_builds_strict(tmp_path: Path) -> None:
    done = subprocess.run(
        [sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(tmp_path)],
        cwd=REPO, env=environment("NO_MKDOCS_2_WARNING=1"), capture_output=True, text=True,
        timeout=600)
    assert done.returncode == 0, done.stderr[-4000:]
    for page in ("index.html", "getting-started.html", "guide/tasks.html",
                 "results/ablation.html", "api/envs.html"):
        assert (tmp_path / page).is_file(), f"the site has no {page}"
    api = (tmp_path / "api" / "envs.html").read_text()
    assert "TaskCore" in api and "Rules" in api, "the API reference renders the docstrings"
    reference = (tmp_path / "guide" / "config-reference.html").read_text()
    for said in ("learner.lr", "lr must be &gt; 0", "Adam learning rate",  # a key's range
                 "env.task.heading_range", "heading_range must be in [0, 180]",  # a task's
                 "ga.schedule.inherited"):
        assert said in reference, f"the configuration reference does not say {said!r}"


def test_the_pages_have_python_snippets() -> None:
    assert len(python_snippets()) >= 2


@pytest.mark.parametrize(("where", "code"), python_snippets(), ids=lambda v: v
                         if ":" in str(v) and "\n" not in str(v) else "")
def test_every_python_snippet_runs(where: str, code: str) -> None:
    done = subprocess.run([sys.executable, "-c", code], cwd=REPO, env=environment(),
                          capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, f"{where}\n{done.stderr[-3000:]}"


def test_the_readme_is_short_and_points_into_the_site() -> None:
    text = README.read_text()
    assert len(text.splitlines()) <= README_LINES
    for link in re.findall(r"\]\((docs/[^)#]+)", text):
        assert (REPO / link).is_file(), f"README links to {link}, which does not exist"
