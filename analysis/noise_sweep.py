"""The noise sweep's trials as a table: ``python -m analysis.noise_sweep table DIR``.

The sweep itself is evo's (``python evo/main.py +exp=noise_sweep``, :mod:`evo.sweep`):
Hydra's Optuna sweeper searches learner and physics settings for a fitness that ranks
structures the same under another seed, at a lower cost (SPEC section 10), each trial a
retraining folder ``<sweep dir>/trials/<digest>/`` with its objectives in
``trial.json``. This module reads the study (``<sweep dir>/optuna.db``) and the trials'
``trial.json`` into the trials' table (``trials.csv``, ``trials.md``) and the frontier
figure (``frontier.png``); ``python -m analysis.noise_ceiling <trial folder>`` writes a
trial's noise-ceiling report.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from dataclasses import asdict
from pathlib import Path
from typing import TYPE_CHECKING

from evo.run.layout import TRIAL
from evo.run.records import read_sweep_trial

if TYPE_CHECKING:
    import pandas as pd

STORAGE = "optuna.db"
"""The study's SQLite file in the sweep folder."""


# ---------------------------------------------------------------- the trials' table


def trials_table(sweep_dir: Path, study_name: str = "noise_sweep") -> pd.DataFrame:
    """One row per trial of the study in ``sweep_dir``: number, state, the measured
    agreement and cost (from the ``trial.json`` of a complete trial), its parameters,
    its folder, and whether it is on the Pareto front (no other trial is as good on
    both)."""
    import optuna
    import pandas as pd

    study = optuna.load_study(study_name=study_name, storage=f"sqlite:///{sweep_dir / STORAGE}")
    measured = {}
    for path in sorted(sweep_dir.glob(f"trials/*/{TRIAL}")):
        found = read_sweep_trial(path)
        assert found is not None
        measured[frozenset(found.overrides)] = {**asdict(found), "folder": path.parent.name}
    rows = []
    for trial in study.get_trials(deepcopy=False):
        params = {k: v for k, v in trial.params.items()}
        wanted = {f"{k}={v}" for k, v in params.items()}
        match = next((m for key, m in measured.items() if wanted <= key), {}
                     ) if trial.state.name == "COMPLETE" else {}
        rows.append({"trial": trial.number, "state": trial.state.name,
                     **{k: match.get(k, float("nan")) for k in (
                         "spearman", "icc", "top_quarter", "core_seconds_per_robot",
                         "env_steps_per_second")},
                     **params, "folder": match.get("folder", "")})
    table = pd.DataFrame(rows)
    if table.empty:
        return table
    value = table["spearman"].to_numpy()
    cost = table["core_seconds_per_robot"].to_numpy()
    table["pareto"] = [bool(v == v) and not ((value >= v) & (cost <= c) & (
        (value > v) | (cost < c))).any() for v, c in zip(value, cost, strict=True)]
    return table


def write_table(sweep_dir: Path, table: pd.DataFrame) -> Path:
    """``trials.csv``, ``trials.md`` and ``frontier.png`` (agreement against cost) in
    ``sweep_dir``; returns the Markdown file."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from analysis.markdown import markdown_table

    table.to_csv(sweep_dir / "trials.csv", index=False)
    fig, ax = plt.subplots(figsize=(6, 4))
    done = table.dropna(subset=["spearman"])
    ax.scatter(done["core_seconds_per_robot"], done["spearman"], c="0.6", label="trial")
    front = done[done["pareto"]].sort_values("core_seconds_per_robot")
    ax.plot(front["core_seconds_per_robot"], front["spearman"], "o-", c="C3", label="frontier")
    for row in done.itertuples():
        ax.annotate(str(row.trial), (row.core_seconds_per_robot, row.spearman), fontsize=7)
    ax.set(xlabel="core-seconds per robot", ylabel="Spearman rho between seeds (Eq. 8)")
    ax.legend()
    fig.tight_layout()
    fig.savefig(sweep_dir / "frontier.png", dpi=120)
    plt.close(fig)
    path = sweep_dir / "trials.md"
    path.write_text("# Noise sweep: trials\n\n" + markdown_table(table.drop(columns="folder"))
                    + "\n![agreement against cost](frontier.png)\n", encoding="utf-8")
    return path


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m analysis.noise_sweep table DIR``: the trials' table of a sweep folder."""
    cli = argparse.ArgumentParser(prog="python -m analysis.noise_sweep",
                                  description="The trials' table of a noise sweep.")
    verbs = cli.add_subparsers(dest="verb", required=True)
    tab = verbs.add_parser("table", help="trials.csv, trials.md and frontier.png")
    tab.add_argument("sweep_dir", type=Path, help="the sweep folder (hydra.sweep.dir)")
    tab.add_argument("--study", default="noise_sweep", help="hydra.sweeper.study_name")
    args = cli.parse_args(argv)
    if not (args.sweep_dir / STORAGE).is_file():
        print(f"error: {args.sweep_dir}: no {STORAGE}; is it a noise sweep folder?",
              file=sys.stderr)
        return 2
    table = trials_table(args.sweep_dir, args.study)
    if table.empty:
        print(f"error: {args.sweep_dir}: the study has no trials yet", file=sys.stderr)
        return 2
    print(f"table: {write_table(args.sweep_dir, table)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
