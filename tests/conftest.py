"""Fixtures several test files share."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest
import torch
from test_evolution import TINY, main_cmd, run

from evo.schemas import register_schemas

# The conf/ files start from these nodes: every test that composes them needs them.
register_schemas()


@pytest.fixture(scope="module")
def serial_reference(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A finished tiny serial evolution (``test_evolution.TINY``): the uninterrupted run
    that interrupted and resumed ones are compared with."""
    run_dir = tmp_path_factory.mktemp("serial") / "run"
    done = run(main_cmd(*TINY, "executor=serial", f"hydra.run.dir={run_dir}"), run_dir.parent)
    assert done.returncode == 0, done.stderr[-3000:]
    return run_dir


@pytest.fixture(scope="module")
def one_thread() -> Iterator[None]:
    """Results are reproducible for a seed on one thread (float sums depend on threads):
    a module that trains uses it with ``pytestmark = pytest.mark.usefixtures(...)``."""
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(threads)
