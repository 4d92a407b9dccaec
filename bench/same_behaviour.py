"""Does a change of the code change what a run computes? Run the same small serial
evolution with a fixed seed on an earlier commit and on the working tree, and compare
what they computed.

    python bench/same_behaviour.py --before REV [--out runs/same_behaviour] [overrides...]

The earlier commit is checked out into ``OUT/tree`` (``git worktree``) and both runs use
this virtualenv. Compared, robot by robot: the ``history.csv`` columns (every one the
earlier commit writes but wall times; columns added since are named, not compared), the
learning curves ``evals/<robot>.csv`` (every column but wall times; curve keys renamed
since are matched through ``evo.record.rows.current_curve_key``, keys added since are
named, not compared) and the policies
``evals/<robot>.pt`` (every tensor, bit for bit). Prints one line per comparison and
exits 0 when everything is identical.
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import pandas as pd
import torch
from kill_resume import RUN as KILL_RESUME_RUN  # bench/ is on sys.path when this runs

from evo.record.rows import current_curve_key

REPO = Path(__file__).resolve().parents[1]
RUN = [*KILL_RESUME_RUN, "record=off"]
"""``bench/kill_resume.py``'s small serial evolution (7 robots of 1-2k env steps,
crossover included), without recordings."""


@contextmanager
def earlier_tree(rev: str, tree: Path) -> Iterator[Path]:
    """``rev`` checked out at ``tree`` (``git worktree``), removed again on leaving."""
    subprocess.run(["git", "worktree", "add", "--detach", "-f", str(tree), rev],
                   cwd=REPO, check=True, capture_output=True)
    try:
        yield tree
    finally:
        subprocess.run(["git", "worktree", "remove", "--force", str(tree)], cwd=REPO,
                       capture_output=True)


def tree_env(tree: Path) -> dict[str, str]:
    """The environment that runs ``tree``'s code (its own packages first on the path)."""
    return {**os.environ, "PYTHONPATH": str(tree), "MUJOCO_GL": "egl"}


def run(tree: Path, run_dir: Path, overrides: list[str]) -> None:
    """``python evo/main.py`` of ``tree`` (its own ``evo`` package first on the path)."""
    done = subprocess.run([sys.executable, str(tree / "evo" / "main.py"), *RUN, *overrides,
                           f"hydra.run.dir={run_dir}"], cwd=tree, env=tree_env(tree),
                          capture_output=True, text=True, timeout=1800)
    if done.returncode != 0:
        raise SystemExit(f"{tree}: the run failed\n{done.stderr[-3000:]}")


def renamed(curve: pd.DataFrame) -> pd.DataFrame:
    """``curve`` with old curve keys under their current names, without wall times."""
    curve = curve.rename(columns=current_curve_key)
    return curve.drop(columns=[c for c in curve if "wall_seconds" in c]).sort_index(axis=1)


def policies_equal(a: Path, b: Path) -> bool:
    """Whether two checkpoints hold the same tensors, bit for bit."""
    sa, sb = (torch.load(p, weights_only=True) for p in (a, b))
    for part in ("actor", "critic"):
        if sa[part].keys() != sb[part].keys():
            return False
        if not all(torch.equal(sa[part][k], sb[part][k]) for k in sa[part]):
            return False
    sizes = [(int(s["obs_size"]), int(s["action_size"])) for s in (sa, sb)]
    return sizes[0] == sizes[1]


def compare(before: Path, after: Path) -> list[str]:
    """One line per difference between the two run directories (none: identical)."""
    diffs = []
    ha, hb = (pd.read_csv(d / "history.csv", keep_default_na=False).drop(
        columns=["wall_seconds"]) for d in (before, after))
    added = [c for c in hb.columns if c not in ha.columns]
    if added:  # columns the later code adds are compared by the tests, not here
        print(f"history: column(s) {', '.join(added)} added; compared on the earlier ones")
        hb = hb[ha.columns]
    if not ha.equals(hb):
        diffs.append(f"history.csv differs:\n{ha.compare(hb) if ha.shape == hb.shape else ''}")
    print(f"history: {len(hb)} robots, fitness {'identical' if ha.equals(hb) else 'DIFFERS'}")
    named: set[str] = set()
    for name in hb["name"]:
        ca, cb = (renamed(pd.read_csv(d / "evals" / f"{name}.csv")) for d in (before, after))
        new_keys = [c for c in cb.columns if c not in ca.columns]
        if new_keys and not named.issuperset(new_keys):  # named once, compared by the tests
            print(f"curves: key(s) {', '.join(new_keys)} added; compared on the earlier ones")
            named.update(new_keys)
        cb = cb.drop(columns=new_keys)
        same_curve = ca.equals(cb)
        same_policy = policies_equal(before / "evals" / f"{name}.pt",
                                     after / "evals" / f"{name}.pt")
        print(f"{name}: curve ({len(cb)} rows) {'identical' if same_curve else 'DIFFERS'}, "
              f"policy {'identical' if same_policy else 'DIFFERS'}")
        if not same_curve:
            diffs.append(f"{name}: curve differs")
        if not same_policy:
            diffs.append(f"{name}: policy differs")
    return diffs


def main() -> int:
    cli = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    cli.add_argument("--before", required=True, help="the earlier commit (any git revision)")
    cli.add_argument("--out", type=Path, default=REPO / "runs" / "same_behaviour")
    cli.add_argument("overrides", nargs="*", help="more config overrides for both runs")
    args = cli.parse_args()
    shutil.rmtree(args.out, ignore_errors=True)
    args.out.mkdir(parents=True)
    with earlier_tree(args.before, args.out / "tree") as tree:
        run(tree, args.out / "before", args.overrides)
        run(REPO, args.out / "after", args.overrides)
        diffs = compare(args.out / "before", args.out / "after")
    print("same behaviour" if not diffs else f"{len(diffs)} difference(s)")
    return 0 if not diffs else 1


if __name__ == "__main__":
    sys.exit(main())
