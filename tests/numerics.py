"""A fingerprint of this machine's floating-point arithmetic, for tests that compare
numbers recorded elsewhere.

A training's numbers are exact on one machine (same seed, same history) but not across
machines: torch picks its kernels by CPU (vector width, BLAS library and vendor) and
MuJoCo's contacts turn the last bit of a difference into another trajectory. A golden
history is therefore exact only where the arithmetic is the one it was recorded with.
``fingerprint()`` hashes what such a training computes, without evo's code: a small MLP's
forward and backward passes and Adam steps, Gaussian samples and their log-probabilities
(torch), and a body with contacts driven by random controls (MuJoCo), with the versions
of torch and MuJoCo (a new MuJoCo release can move a robot's contacts while this small
body's stay the same, as 4.0.1 did). Data that holds
recorded numbers stores the fingerprint of the machine that made it (``numerics.txt``
beside it); a test compares them exactly where the fingerprints agree and compares
only what arithmetic cannot change elsewhere. On any machine, ``bench/same_behaviour.py``
compares two commits of the code exactly.
"""

from __future__ import annotations

import functools
import hashlib
from pathlib import Path

import mujoco
import numpy as np
import pandas as pd
import torch

_SCENE = """
<mujoco>
  <option timestep="0.005"/>
  <worldbody>
    <geom type="plane" size="5 5 0.1"/>
    <body pos="0 0 0.2">
      <freejoint/>
      <geom type="box" size="0.05 0.05 0.05" mass="0.3"/>
      <body pos="0.1 0 -0.01">
        <joint name="wheel" type="hinge" axis="0 1 0" armature="0.01" damping="0.01"/>
        <geom type="cylinder" size="0.04 0.01" euler="90 0 0" friction="1.5"/>
      </body>
    </body>
  </worldbody>
  <actuator><velocity joint="wheel" kv="0.1" ctrlrange="-10 10"/></actuator>
</mujoco>
"""


def _torch_bytes() -> bytes:
    with torch.random.fork_rng():
        torch.manual_seed(0)
        net = torch.nn.Sequential(torch.nn.Linear(37, 64), torch.nn.Tanh(),
                                  torch.nn.Linear(64, 64), torch.nn.Tanh(),
                                  torch.nn.Linear(64, 8))
        optimiser = torch.optim.Adam(net.parameters(), lr=3e-4)
        x = torch.randn(512, 37)
        for _ in range(5):
            loc = net(x)
            dist = torch.distributions.Normal(loc, torch.ones_like(loc) * 0.6)
            loss = -dist.log_prob(dist.sample()).mean()
            optimiser.zero_grad()
            loss.backward()
            optimiser.step()
        with torch.no_grad():
            return net(x).numpy().tobytes() + torch.randn(4096).numpy().tobytes()


def _mujoco_bytes() -> bytes:
    model = mujoco.MjModel.from_xml_string(_SCENE)
    data = mujoco.MjData(model)
    controls = np.random.default_rng(0).uniform(-10, 10, size=2000)
    for control in controls:
        data.ctrl[0] = control
        mujoco.mj_step(model, data)
    return data.qpos.tobytes() + data.qvel.tobytes()


@functools.cache
def fingerprint() -> str:
    """This machine's arithmetic, as 16 hex digits (on one thread, as a training runs)."""
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        versions = f"torch {torch.__version__} mujoco {mujoco.__version__}".encode()
        return hashlib.sha256(versions + _torch_bytes() + _mujoco_bytes()).hexdigest()[:16]
    finally:
        torch.set_num_threads(threads)


def recorded_here(folder: Path) -> bool:
    """Whether the numbers in ``folder`` were recorded with this machine's arithmetic
    (its ``numerics.txt`` holds this machine's fingerprint)."""
    stamp = folder / "numerics.txt"
    return stamp.is_file() and stamp.read_text().split()[0] == fingerprint()


def stamp(folder: Path) -> Path:
    """Record this machine's fingerprint beside data made on it."""
    path = folder / "numerics.txt"
    path.write_text(f"{fingerprint()}  fingerprint of the arithmetic that made these "
                    "numbers (tests/numerics.py)\n")
    return path


ARITHMETIC_FREE = ["birth", "method", "budget", "seed", "env_steps"]
"""History columns that no floating-point result decides: the schedule gives a birth its
budget and seed whatever the fitnesses were."""


def assert_same_history(history: pd.DataFrame, recorded: pd.DataFrame, folder: Path,
                        population: int) -> None:
    """``history`` is ``recorded`` (made with the arithmetic stamped in ``folder``): every
    cell where this machine's arithmetic is that one; elsewhere the columns no float
    decides, and the names of the first ``population`` robots, drawn from the seed."""
    if recorded_here(folder):
        pd.testing.assert_frame_equal(history, recorded)
        return
    pd.testing.assert_frame_equal(history[ARITHMETIC_FREE].astype(str),
                                  recorded[ARITHMETIC_FREE].astype(str))
    assert list(history["name"][:population]) == list(recorded["name"][:population])
