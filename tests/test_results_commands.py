"""The results pages' analyses read their committed data again, as the pages show them:
each command of ``docs/results/*.md`` that reads what ``docs/results/`` keeps (the runs'
small files, the trainings' tables) runs in a copy of the repository root, its output
sent out of ``docs/results`` by a second ``--out`` (``tests/readme_commands.py``, group
``"results"``). The experiments that made the data take hours; they are excluded there,
each with its reason.
"""

from __future__ import annotations

import re
import subprocess

import pytest
from readme_commands import REPO, RESULTS, Command, Made, copy_of_the_root, group, how, run

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def made(tmp_path_factory: pytest.TempPathFactory) -> Made:
    """A copy of the root the results commands share (the copies of the runs first)."""
    return Made(copy_of_the_root(tmp_path_factory.mktemp("root")))


def test_the_results_pages_have_commands_that_run() -> None:
    assert len(group(RESULTS)) >= 10


def docs_results() -> str:
    """What git sees changed in the checkout's docs/results."""
    return subprocess.run(["git", "status", "--porcelain", "--untracked-files=all", "--",
                           "docs/results"], cwd=REPO, capture_output=True, text=True,
                          check=True).stdout


@pytest.mark.parametrize("command", group(RESULTS), ids=lambda c: c.text)
def test_the_results_command_reads_the_committed_data(made: Made, command: Command) -> None:
    before = docs_results()
    run(command, made.root, made)
    assert docs_results() == before, f"{command.text} changed the checkout's docs/results"


def test_no_results_command_writes_into_docs_results() -> None:
    """A command whose ``--out`` names docs/results runs with a second ``--out``."""
    for command in group(RESULTS):
        if re.search(r"--out docs/", command.text):
            assert "--out " in how(command).append, f"{command.text} would write docs/results"
