"""``bench/train_throughput.py --profile``: profiled time is put on the right library."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "bench"))
from train_throughput import library_of, profile_by_library  # noqa: E402


def test_functions_are_put_on_their_library() -> None:
    site = "/venv/lib/python3.11/site-packages"
    assert library_of(f"{site}/tensordict/base.py", "get") == "tensordict"
    assert library_of(f"{site}/torchrl/envs/utils.py", "_grab_and_place") == "torchrl"
    assert library_of(f"{site}/torch/nn/modules/module.py", "_call_impl") == "torch"
    assert library_of("~", "<built-in method mujoco._batch.step>") == "mujoco"
    assert library_of("~", "<built-in method torch._C._nn.linear>") == "torch"
    assert library_of("/repo/evo/envs/task.py", "_observe") == "evo"
    assert library_of("/usr/lib/python3.11/json/decoder.py", "decode") == "python"


def test_the_profile_table_names_the_libraries_that_took_the_time() -> None:
    def work() -> None:
        x = torch.randn(256, 256)
        for _ in range(50):
            x = torch.tanh(x @ x)
        np.linalg.svd(np.random.default_rng(0).normal(size=(200, 200)))

    table = profile_by_library(work, "work")
    libraries = list(table.columns[0].cells)
    assert "torch" in libraries and "numpy" in libraries
    shares = [float(s.rstrip("%")) for s in table.columns[1].cells]
    assert shares == sorted(shares, reverse=True) and 95 <= sum(shares) <= 105
