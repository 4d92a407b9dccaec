"""Fault injection: SIGKILL a small serial evolution at random moments, resume after
each kill, and compare the result with an uninterrupted run of the same seed.

    python bench/kill_resume.py --kills 20 [--seed 0] [--out runs/kill_resume]

Each kill lands at a random moment of one of five kinds, drawn with the harness's own
seed: during an evaluation (inside training, at the k-th learning-curve batch),
during a state write (``state.json`` half written to its temporary file), during
recording (inside an evaluation recorder's or the run recorder's write), between
robots (just after a result was saved, nothing in flight), or at a random wall-clock
time. The first attempt starts the run (``python evo/main.py``); every later one is
``python evo/main.py resume=<dir>``; after the last kill one more resume finishes it.

Printed: kills that landed, robots lost, robots recorded twice, whether the history
(every column but wall times) equals the uninterrupted one, and whether every
``.mcap`` (read back by evo's own reader) and every ``.rrd`` (``rerun rrd verify``)
is readable. Goal: 0 lost, 0 twice, identical, all readable. Exits 0 when it is met.
"""

from __future__ import annotations

import argparse
import os
import shutil
import signal
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

REPO = Path(__file__).resolve().parents[1]
RUN = [
    "+exp=smoke", "executor=serial", "ga.population_size=3", "ga.robot_budget=7",
    "ga.schedule.initial=1024", "ga.schedule.first=1024", "ga.schedule.last=2048",
    "learner.num_envs=4", "learner.rollout_steps=64", "learner.epochs=1",
    "learner.minibatch_size=128", "learner.hidden=[32,32]", "env.task.t_max=40",
    "record.episodes.every=2",
]
"""A small serial evolution, recorded: 7 robots of 1-2k env steps each."""
KINDS = ("evaluation", "state-write", "recording", "between", "time")

DRIVER = Path(__file__).with_name("kill_at.py")
"""Runs evo/main.py killed at the k-th event of a kind (``python bench/kill_at.py KIND K
...``); tests/test_evolution.py drives its SIGKILL tests with it too."""


@dataclass(frozen=True)
class Verdict:
    """What the harness measured."""

    kills: int
    landed: int
    lost: int
    twice: int
    identical: bool
    unreadable: list[str]

    @property
    def ok(self) -> bool:
        return (self.lost == 0 and self.twice == 0 and self.identical
                and not self.unreadable)


def main_cmd(*args: str) -> list[str]:
    return [sys.executable, str(REPO / "evo" / "main.py"), *args]


def env() -> dict[str, str]:
    return {**os.environ, "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl")}


def attempt(args: list[str], kind: str, k: int, delay: float, cwd: Path) -> bool:
    """One run or resume, killed at the ``k``-th event of ``kind``; whether it was."""
    if kind == "time":
        with subprocess.Popen(main_cmd(*args), cwd=cwd, env=env(), stdout=subprocess.DEVNULL,
                              stderr=subprocess.DEVNULL) as proc:
            try:
                proc.wait(timeout=delay)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()
            return proc.returncode == -signal.SIGKILL
    done = subprocess.run([sys.executable, str(DRIVER), kind, str(k), *args], cwd=cwd,
                          env=env(), capture_output=True, text=True, timeout=600)
    if done.returncode not in (0, -signal.SIGKILL):
        raise RuntimeError(f"{kind} kill: the run failed (exit {done.returncode}):\n"
                           f"{done.stderr[-3000:]}")
    return done.returncode == -signal.SIGKILL


def comparable(run_dir: Path) -> pd.DataFrame:
    history = pd.read_csv(run_dir / "history.csv", dtype=str, keep_default_na=False)
    return history.drop(columns=["wall_seconds"]).sort_values(
        "birth", key=lambda b: b.astype(int)).reset_index(drop=True)


def unreadable_files(run_dir: Path, names: tuple[str, ...] = ()) -> list[str]:
    """The run's recordings (all, or those ``names``) that do not read back (MCAP, with
    evo's own readers) or verify (``rerun rrd verify``)."""
    from evo.record import read_births, read_curve, read_metadata

    bad = []
    chosen = [run_dir / n for n in names] if names else list(run_dir.glob("**/*"))
    for path in sorted(p for p in chosen if p.suffix == ".mcap"):
        try:
            if path.name == "run.mcap":
                read_births(path)
            else:
                read_metadata(path)
                read_curve(path)
        except Exception as err:  # noqa: BLE001 - reported, whatever the reader raised
            bad.append(f"{path.name} ({type(err).__name__})")
    rerun = shutil.which("rerun", path=str(Path(sys.executable).parent)) or "rerun"
    for path in sorted(p for p in chosen if p.suffix == ".rrd"):
        check = subprocess.run([rerun, "rrd", "verify", str(path)], capture_output=True)
        if check.returncode != 0:
            bad.append(f"{path.name} (rrd verify)")
    return bad


def kill_and_resume(kills: int, seed: int, out: Path, log: bool = True) -> Verdict:
    """Run the harness in ``out`` (emptied first) and measure the result."""
    shutil.rmtree(out, ignore_errors=True)
    out.mkdir(parents=True)
    reference, run_dir = out / "uninterrupted", out / "killed"
    done = subprocess.run(main_cmd(*RUN, f"hydra.run.dir={reference}"), cwd=out, env=env(),
                          capture_output=True, text=True, timeout=600)
    if done.returncode != 0:
        raise RuntimeError(f"the uninterrupted run failed:\n{done.stderr[-3000:]}")
    rng = np.random.default_rng(seed)
    landed = 0
    for i in range(kills):
        kind, k = str(rng.choice(KINDS)), int(rng.integers(1, 4))
        delay = float(rng.uniform(3.0, 9.0))  # Python and Hydra take ~3 s to start
        args = ([*RUN, f"hydra.run.dir={run_dir}"] if not (run_dir / "config.yaml").is_file()
                else [f"resume={run_dir}"])
        tick = time.perf_counter()
        hit = attempt(args, kind, k, delay, out)
        landed += hit
        if log:
            what = f"after {delay:.1f} s" if kind == "time" else f"at event {k}"
            print(f"kill {i + 1:2d}/{kills}: {kind:<11} {what:<13} "
                  f"{'killed' if hit else 'finished first'} ({time.perf_counter() - tick:.1f} s)",
                  flush=True)
    done = subprocess.run(main_cmd(f"resume={run_dir}"), cwd=out, env=env(),
                          capture_output=True, text=True, timeout=600)
    if done.returncode != 0:
        raise RuntimeError(f"the final resume failed:\n{done.stderr[-3000:]}")
    ours, theirs = comparable(run_dir), comparable(reference)
    births = ours["birth"].astype(int)
    lost = len(set(theirs["birth"].astype(int)) - set(births))
    twice = int(births.duplicated().sum())
    return Verdict(kills, landed, lost, twice, ours.equals(theirs), unreadable_files(run_dir))


def main() -> int:
    cli = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    cli.add_argument("--kills", type=int, default=20)
    cli.add_argument("--seed", type=int, default=0, help="seed of the kill moments")
    cli.add_argument("--out", type=Path, default=Path("runs/kill_resume"))
    args = cli.parse_args()
    tick = time.perf_counter()
    verdict = kill_and_resume(args.kills, args.seed, args.out)
    print(f"kills: {verdict.kills} ({verdict.landed} landed before the run finished)")
    print(f"robots lost: {verdict.lost}")
    print(f"robots recorded twice: {verdict.twice}")
    print(f"history identical to the uninterrupted run: {'yes' if verdict.identical else 'NO'}")
    print(f"recordings readable: "
          f"{'all' if not verdict.unreadable else ', '.join(verdict.unreadable)}")
    print(f"goal (0 lost, 0 twice, identical, all readable): "
          f"{'met' if verdict.ok else 'NOT met'} in {time.perf_counter() - tick:.0f} s")
    return 0 if verdict.ok else 1


if __name__ == "__main__":
    sys.exit(main())
