"""Does a change of the code change what the analysis writes? Run the analysis commands
of ``docs/results`` on the committed runs with an earlier commit and with the working
tree, and compare every file they write.

    python bench/same_analysis.py --before REV [--out runs/same_analysis] [--only NAME ...]

The earlier commit is checked out into ``OUT/tree`` (``git worktree``, as
``bench/same_behaviour.py`` does) and both sides use this virtualenv. Each command runs
once per side in a folder of its own (``OUT/before/<name>``, ``OUT/after/<name>``) that
holds a copy of its inputs under the same relative path, so that paths the outputs name
are alike. The inputs are the working tree's committed files on both sides (the code is
compared, not the data, some of which grew since), but for data that moved: an earlier
commit that lacks the working tree's path reads its own copy (the 100k ablation's runs
were ``docs/results/ablation/runs`` before they were ``docs/results/ablation_100k/runs``,
and that path now holds the 13-seed ablation), and a line says whether the two copies
are identical. The commands (``docs/results/*/README.md``):

* ``report``: ``python -m analysis.report RUNS --history-only --first 60 --out OUT`` on
  the 100k ablation's committed ``history.csv`` and ``summary.json`` copies;
* ``power``: ``python -m analysis.power RUNS --history-only --first 60`` (what it prints);
* ``ablation``, ``ablation_power``: the same two on the 13-seed ablation
  (``docs/results/ablation/runs``), the power for its fifth arm's question
  (``--pair E+L+I E+L``);
* ``equal_cost``: ``python -m analysis.equal_cost --without .. --with .. --out OUT`` on
  ``docs/results/early_rejection/runs`` (each run given a ``config.yaml`` with its GA
  seed: see :class:`Input`);
* ``noise_ceiling``: the report of a committed noise-ceiling folder
  (``fitness_noise/default_100k``) regenerated from its ``trainings.csv`` by
  ``analysis.noise_ceiling.write_report``, as the tool writes it after the trainings,
  with the settings, wall time and command of its ``summary.json``;
* ``noise_study``: ``python -m analysis.noise_study table`` of every committed cell;
* ``inheritance``: ``python -m analysis.inheritance RUNS --out OUT``;
* ``noise_sweep``: ``python -m analysis.noise_sweep table STUDY``.

The early-slope study is not among them: it reads every robot's learning curve
(``evals/<robot>.mcap``), which is not committed.

Compared: every file a command creates or changes, and what it prints (``stdout.txt``),
byte for byte; a PNG whose bytes differ is compared by its decoded pixels (a figure's
metadata, such as the Matplotlib version, may differ while the picture does not), and
reported so. A command the earlier commit cannot run (it did not exist yet, or read
other files) is named, with its error, and not counted as a difference. Prints one line
per output and exits 0 when every compared output is identical.
"""

from __future__ import annotations

import argparse
import hashlib
import re
import shutil
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from matplotlib.image import imread
from same_behaviour import REPO, earlier_tree, tree_env  # bench/ is on sys.path

RESULTS = Path("docs/results")

ONLY_THE_TREE = ("import sys\nsys.meta_path[:] = [f for f in sys.meta_path "
                 "if '__editable__' not in getattr(f, '__module__', '')]\n")
"""Drops the virtualenv's editable-install finder, which would import a module the tree
lacks (``analysis.power`` at a commit before it existed) from the checkout it was
installed from: each side imports its own tree's code or fails."""

NOISE_REPORT = """
import json, sys
from pathlib import Path
import analysis.noise_ceiling as nc
try:
    from evo.run.records import RetrainSettings as Settings, read_trainings
    def trainings(out): return read_trainings(out / "trainings.csv")
except ImportError:  # before the retraining's records were evo.run.records'
    try:
        from evo.retrain import Settings, read_trainings
    except ImportError:  # before the trainings moved to evo.retrain
        from analysis.noise_ceiling import Settings, read_trainings
    def trainings(out): return read_trainings(out)
out = Path(sys.argv[1])
summary = json.loads((out / "summary.json").read_text())
settings = Settings(**{k: tuple(v) if isinstance(v, list) else v
                       for k, v in summary["settings"].items()})
nc.write_report(out, trainings(out), settings, wall_seconds=summary["wall_seconds"],
                command=summary["command"])
"""
"""Writes a noise-ceiling folder's report again from its trainings (either tree's code)."""


@dataclass(frozen=True)
class Input:
    """A committed file or folder a command reads, copied to ``at`` in its folder.

    Attributes:
        at: Where the command finds it, relative to its folder.
        now: Its path in the working tree (what both sides read by default).
        before: Its path at the earlier commit, when it was elsewhere (the earlier side
            reads that copy where the commit has it and lacks ``now``).
        seed_configs: Give each run directory ``seed<S>`` under it that has no
            ``config.yaml`` one that says ``seed: S`` (the committed copies of the
            early-rejection runs have none, and the equal-cost table reads the GA seed
            from it; the rest of the config is the GA's defaults for the table).
    """

    at: str
    now: Path
    before: Path | None = None
    seed_configs: bool = False


@dataclass(frozen=True)
class Command:
    """One analysis command: ``python ARGS`` run in its own folder."""

    name: str
    args: tuple[str, ...]
    inputs: tuple[Input, ...]

    def argv(self) -> list[str]:
        """``python ARGS`` (``-m MODULE ...`` or ``-c CODE ...``) importing only a tree's
        own code (:data:`ONLY_THE_TREE`)."""
        kind, what, *rest = self.args
        code = (f"import runpy\nrunpy.run_module({what!r}, run_name='__main__', "
                "alter_sys=True)" if kind == "-m" else what)
        return [sys.executable, "-c", ONLY_THE_TREE + code, *rest]


ABLATION = Input("runs", RESULTS / "ablation_100k/runs", RESULTS / "ablation/runs")
SEEDS_13 = Input("runs", RESULTS / "ablation/runs")
EARLY = RESULTS / "early_rejection/runs"
COMMANDS = (
    Command("report", ("-m", "analysis.report", "runs", "--history-only", "--first", "60",
                       "--out", "out"), (ABLATION,)),
    Command("power", ("-m", "analysis.power", "runs", "--history-only", "--first", "60"),
            (ABLATION,)),
    Command("ablation", ("-m", "analysis.report", "runs", "--history-only", "--first", "60",
                         "--out", "out"), (SEEDS_13,)),
    Command("ablation_power", ("-m", "analysis.power", "runs", "--history-only", "--first",
                               "60", "--pair", "E+L+I", "E+L"), (SEEDS_13,)),
    Command("equal_cost", ("-m", "analysis.equal_cost", "--without", "runs/paper_clean",
                           "--with", "runs/paper_clean_early", "--out", "out"),
            (Input("runs", EARLY, seed_configs=True),)),
    Command("noise_ceiling", ("-c", NOISE_REPORT, "default_100k"),
            (Input("default_100k", RESULTS / "fitness_noise/default_100k"),)),
    Command("noise_study", ("-m", "analysis.noise_study", "table", "fitness_noise", "--out",
                            "out/fitness_noise.md", "--notes", "fitness_noise/notes.md"),
            (Input("fitness_noise", RESULTS / "fitness_noise"),)),
    Command("inheritance", ("-m", "analysis.inheritance", "runs", "--out", "out"),
            (Input("runs", RESULTS / "inheritance/runs"),)),
    Command("noise_sweep", ("-m", "analysis.noise_sweep", "table", "study"),
            (Input("study", RESULTS / "noise_sweep/study"),)),
)


def digest(path: Path) -> str:
    """The SHA-256 of a file's bytes."""
    return hashlib.sha256(path.read_bytes()).hexdigest()


def digests(folder: Path) -> dict[str, str]:
    """Every file under ``folder`` (relative path) and its :func:`digest`."""
    return {p.relative_to(folder).as_posix(): digest(p)
            for p in sorted(folder.rglob("*")) if p.is_file()}


def written(folder: Path) -> dict[str, int]:
    """Every file under ``folder`` (relative path) and when it was last written (ns)."""
    return {p.relative_to(folder).as_posix(): p.stat().st_mtime_ns
            for p in sorted(folder.rglob("*")) if p.is_file()}


def place(source: Path, target: Path, *, seed_configs: bool = False) -> None:
    """Copy the file or folder ``source`` to ``target`` (see :class:`Input`)."""
    target.parent.mkdir(parents=True, exist_ok=True)
    if source.is_dir():
        shutil.copytree(source, target)
    else:
        shutil.copy2(source, target)
    for history in target.rglob("history.csv") if seed_configs else ():
        match = re.fullmatch(r"seed(\d+)", history.parent.name)
        if match is not None and not (history.parent / "config.yaml").exists():
            (history.parent / "config.yaml").write_text(f"seed: {match.group(1)}\n")


def run(command: Command, tree: Path, folder: Path) -> str | None:
    """Run ``command`` with ``tree``'s code in ``folder``; leave there the files it wrote
    and ``stdout.txt``, and return None, or its error when it failed."""
    folder.mkdir(parents=True)
    for given in command.inputs:
        source = REPO / given.now
        if (tree != REPO and given.before is not None and (tree / given.before).exists()
                and not (tree / given.now).exists()):
            source = tree / given.before
            same = digests(source) == digests(REPO / given.now)
            print(f"{command.name}: reads {given.before} at the earlier commit, "
                  f"{'identical to' if same else 'NOT the same files as'} {given.now}")
        place(source, folder / given.at, seed_configs=given.seed_configs)
    inputs = written(folder)
    done = subprocess.run(command.argv(), cwd=folder, env=tree_env(tree),
                          capture_output=True, text=True, timeout=1800)
    (folder / "stdout.txt").write_text(done.stdout)
    for name, when in inputs.items():  # an input it did not write again is no output
        if (folder / name).is_file() and (folder / name).stat().st_mtime_ns == when:
            (folder / name).unlink()
    if done.returncode != 0:
        lines = done.stderr.strip().splitlines() or [""]
        return f"exit {done.returncode}: {lines[-1]}"
    return None


def same_pixels(a: Path, b: Path) -> bool:
    """Whether two PNG files decode to the same pixels."""
    pa, pb = np.asarray(imread(a)), np.asarray(imread(b))
    return pa.shape == pb.shape and bool(np.array_equal(pa, pb))


def compare(name: str, before: Path, after: Path) -> list[str]:
    """One line per output of command ``name`` that differs (none: identical)."""
    da, db = digests(before), digests(after)
    diffs = []
    for path in sorted(da.keys() | db.keys()):
        if path not in da or path not in db:
            diffs.append(f"{name}: {path} written only {'after' if path in db else 'before'}")
        elif da[path] == db[path]:
            print(f"{name}: {path} identical")
        elif path.endswith(".png") and same_pixels(before / path, after / path):
            print(f"{name}: {path} same pixels (the PNG's bytes differ)")
        else:
            diffs.append(f"{name}: {path} DIFFERS")
    for line in diffs:
        print(line)
    return diffs


def main() -> int:
    cli = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    cli.add_argument("--before", required=True, help="the earlier commit (any git revision)")
    cli.add_argument("--out", type=Path, default=REPO / "runs" / "same_analysis")
    cli.add_argument("--only", nargs="+", choices=[c.name for c in COMMANDS],
                     help="these commands only")
    args = cli.parse_args()
    chosen = [c for c in COMMANDS if args.only is None or c.name in args.only]
    out = args.out.resolve()
    shutil.rmtree(out, ignore_errors=True)
    out.mkdir(parents=True)
    diffs, skipped = [], []
    with earlier_tree(args.before, out / "tree") as tree:
        for command in chosen:
            failed = run(command, tree, out / "before" / command.name)
            if failed is not None:
                print(f"{command.name}: not compared: {args.before} cannot run it ({failed})")
                skipped.append(command.name)
                continue
            if (error := run(command, REPO, out / "after" / command.name)) is not None:
                diffs.append(f"{command.name}: the working tree failed ({error})")
                print(diffs[-1])
                continue
            diffs += compare(command.name, out / "before" / command.name,
                             out / "after" / command.name)
    compared = len(chosen) - len(skipped)
    print(f"{compared} command(s) compared"
          + (f", {len(skipped)} not at {args.before} ({', '.join(skipped)})" if skipped else "")
          + (": same analysis" if not diffs else f": {len(diffs)} difference(s)"))
    return 0 if not diffs else 1


if __name__ == "__main__":
    sys.exit(main())
