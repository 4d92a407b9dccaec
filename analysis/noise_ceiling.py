"""The noise ceiling's report: how much of a structure's fitness is the structure, not the
seed.

Fitness is the GA's only signal (SPEC §10). A retraining (``python evo/main.py
+exp=retrain``, ``evo.retrain``) trains every structure of a sample K ≥ 2 times with
independent seeds under one config; this module asks how well one training ranks the
structures as another does, with the statistics of :mod:`evo.fidelity`:

* Spearman ρ and Kendall τ-b between the seeds (the mean over seed pairs when K > 2);
* the intraclass correlation ICC(1) of a one-way random-effects model: the share of
  fitness variance that lies between structures rather than between seeds;
* top-quarter agreement: the share of one seed's top 25 % that is also in the other's;
* the share of structures whose fitness (mean over seeds) clears the random learner's
  on the same structure (the untrained policy for the same env steps) by more than
  :data:`CLEAR_MARGIN`: structures for which training did anything at all;

each with a bootstrap CI over structures, for every fitness estimator:

* ``fitness``: the paper's Eq. 8, the mean return of every episode completed during
  training (the GA's default);
* ``fitness_late``: the mean return of the episodes completed in the second half of
  the budget, an alternative that drops the untrained start.

No early predictor can rank structures by fitness better than a second training does,
so the same numbers bound the early-slope study (``analysis.early_slope_report``).

    python evo/main.py +exp=retrain retrain.random=24 retrain.budget=100000 \
        hydra.run.dir=runs/noise [overrides...]           # the trainings (evo)
    python -m analysis.noise_ceiling runs/noise [--resamples R]   # the report

The report is ``noise_ceiling.md``, ``noise_ceiling.csv`` (the metrics),
``noise_ceiling.png`` (fitness under one seed against another, one point per
structure) and ``summary.json`` (settings, command, env steps, wall time, metrics),
beside the folder's ``trainings.csv`` (one row per training), ``robots/`` and ``evals/``.

``python -m analysis.noise_ceiling --robots DIR | --random N --seed S [--seeds K]
--out DIR [--budget B] [--no-baseline] [--resamples R] [overrides...]`` is the older
one-shot command: it runs the retrain task (``--out`` its run directory, the other
options its ``retrain`` keys, ``--seed`` the root seed; the overrides compose the config
exactly as ``python evo/main.py <overrides>`` composes it), then writes the report.
Either way the trainings run through the config's executor and resume: run it again
with the same arguments and finished trainings are reused.
"""

from __future__ import annotations

import argparse
import json
import shlex
import sys
import warnings
from collections.abc import Sequence
from pathlib import Path
from typing import TypedDict

import numpy as np
import pandas as pd
import scipy.stats
from numpy.typing import NDArray

from analysis.evo_task import run_evo
from analysis.markdown import fmt_ci, markdown_table
from analysis.stats import Resampling, bootstrap_ci
from analysis.tables import require_columns
from evo.fidelity import (
    CLEAR_MARGIN,
    ESTIMATORS,
    METRICS,
    Statistic,
    by_role,
    clears,
    icc,
    seed_columns,
    statistics,
)
from evo.run import layout as files
from evo.run.layout import RetrainLayout
from evo.run.records import (
    RetrainSettings,
    read_progress,
    read_retrain_settings,
    read_trainings,
)

__all__ = ["CLEAR_MARGIN", "ESTIMATORS", "METRICS", "icc"]  # shown with the report's names

REPORT, SETTINGS, TRAININGS = files.CEILING_REPORT, files.RETRAIN_SETTINGS, files.TRAININGS
"""The report's, the settings' and the trainings' file names (``evo.run.layout``)."""


class NoiseCeilingError(ValueError):
    """A folder that holds no retraining, or too few trainings; the message names it."""


class TooFewTrainings(NoiseCeilingError):
    """Fewer than 3 structures have two finished trainings: no rank correlation yet."""


class Summary(TypedDict):
    """``summary.json`` of a noise-ceiling folder."""

    settings: dict[str, object]  # RetrainSettings.record() without the resolved config
    command: str
    trainings: int
    env_steps: int
    wall_seconds: float
    training_seconds: float
    steps_per_second: float
    metrics: dict[str, dict[str, float]]  # estimator -> metric (and CI bound) -> value


# ---------------------------------------------------------------- metrics


def noise_ceiling(
    trainings: pd.DataFrame,
    resampling: Resampling,
    *,
    structure: str = "structure",
    seed: str = "train_seed",
    value: str = "fitness",
    baseline: pd.Series | None = None,
) -> pd.Series:
    """Seed-to-seed agreement of the fitness of the same structures (module docstring).

    Args:
        trainings: One row per (structure, training seed) with its ``value``; a
            structure trained under only some seeds is left out.
        resampling: How the intervals are drawn (structures are the resampled unit).
        structure: Column naming the structure.
        seed: Column naming the training seed (or replicate).
        value: Fitness column.
        baseline: The random learner's fitness per structure (indexed by structure),
            or None: then ``clears_baseline`` is NaN.

    Returns:
        Every metric of :data:`METRICS` with ``<metric>_low`` and ``<metric>_high``,
        ``n_structures`` (those with every seed present) and ``n_seeds``.

    Raises:
        ValueError: With fewer than two training seeds.
    """
    require_columns(trainings, (structure, seed, value), "trainings table")
    wide = seed_columns(trainings, value, structure=structure, seed=seed)
    k = wide.shape[1]
    if k < 2:
        raise ValueError(f"noise ceiling needs at least two values of {seed!r}, got {k}")
    columns = [wide[c].to_numpy(dtype=float) for c in wide.columns]
    out: dict[str, float] = {}
    for name, statistic in statistics(k).items():
        out.update(_with_ci(name, columns, statistic, resampling))
    base = None if baseline is None else baseline.reindex(wide.index).to_numpy(dtype=float)
    if base is None or not np.isfinite(base).all():
        out.update(clears_baseline=np.nan, clears_baseline_low=np.nan,
                   clears_baseline_high=np.nan)
    else:
        out.update(_with_ci("clears_baseline", [*columns, base], clears(k), resampling))
    return pd.Series(dict(**out, n_structures=len(wide), n_seeds=k))


def _with_ci(name: str, columns: list[NDArray[np.float64]], statistic: Statistic,
             resampling: Resampling) -> dict[str, float]:
    if len(columns[0]) < 3:
        return {name: np.nan, f"{name}_low": np.nan, f"{name}_high": np.nan}
    with warnings.catch_warnings():  # constant resamples: the statistic is NaN there
        warnings.simplefilter("ignore", scipy.stats.ConstantInputWarning)
        warnings.simplefilter("ignore", scipy.stats.DegenerateDataWarning)
        estimate = float(statistic(*columns))
        low, high = bootstrap_ci(columns, statistic, resampling, paired=True)
    return {name: estimate, f"{name}_low": low, f"{name}_high": high}


def ceiling_table(trainings: pd.DataFrame, resampling: Resampling) -> pd.DataFrame:
    """Every estimator's noise ceiling from a ``trainings.csv`` table.

    The ``seed`` trainings give the seeds; the ``baseline`` trainings (the random
    learner), when present, give the baseline.

    Returns:
        One row per estimator of :data:`ESTIMATORS`: its metrics as
        :func:`noise_ceiling` returns them.
    """
    require_columns(trainings, ("structure", "role", "replicate", *ESTIMATORS),
                    "trainings table")
    seeds, base = by_role(trainings)
    rows = []
    for estimator in ESTIMATORS:
        baseline = base.groupby("structure")[estimator].mean() if len(base) else None
        ceiling = noise_ceiling(seeds, resampling, seed="replicate", value=estimator,
                                baseline=baseline)
        rows.append(dict(estimator=estimator, **ceiling))
    return pd.DataFrame(rows)


# ---------------------------------------------------------------- report


def write_report(out: Path, trainings: pd.DataFrame, settings: RetrainSettings, *,
                 wall_seconds: float, command: str, resampling: Resampling | None = None
                 ) -> Summary:
    """``noise_ceiling.md``, ``.csv``, ``.png`` and ``summary.json`` from the trainings;
    returns what ``summary.json`` holds (:func:`read_summary` reads it back)."""
    from analysis.plots import plot_seed_scatter

    table = ceiling_table(trainings, resampling or Resampling.seeded(0))
    layout = RetrainLayout(out)
    table.to_csv(layout.metrics, index=False)
    seeds, base = by_role(trainings)
    plot_seed_scatter(seeds, base, estimators=list(ESTIMATORS), ceiling=table,
                      margin=CLEAR_MARGIN, path=layout.figure)
    steps = int(trainings["env_steps"].sum())
    summary = Summary(
        settings=_shown(settings), command=command,
        trainings=len(trainings), env_steps=steps, wall_seconds=wall_seconds,
        training_seconds=float(trainings["wall_seconds"].sum()),
        steps_per_second=steps / max(wall_seconds, 1e-9),
        metrics={row["estimator"]: {k: v for k, v in row.items() if k != "estimator"}
                 for row in table.to_dict("records")},
    )
    layout.summary.write_text(json.dumps(summary, indent=2, default=float) + "\n")
    layout.report.write_text(_markdown(table, trainings, settings, summary), encoding="utf-8")
    return summary


def read_summary(out: Path) -> Summary | None:
    """``summary.json`` of the noise-ceiling folder ``out``, as :func:`write_report`
    wrote it; None when the folder has none (its report is not written yet)."""
    path = RetrainLayout(out).summary
    if not path.is_file():
        return None
    summary: Summary = json.loads(path.read_text(encoding="utf-8"))
    return summary


def _markdown(table: pd.DataFrame, trainings: pd.DataFrame, settings: RetrainSettings,
              summary: Summary) -> str:
    cells = pd.DataFrame({
        "estimator": table["estimator"],
        **{metric: [fmt_ci(r[metric], r[f"{metric}_low"], r[f"{metric}_high"])
                    for r in table.to_dict("records")] for metric in METRICS},
        "structures": table["n_structures"].astype(int),
    })
    seeds, base = by_role(trainings)
    per_structure = seeds.pivot_table(index="structure", columns="replicate",
                                      values="fitness").add_prefix("seed ")
    if len(base):
        per_structure["random learner"] = base.groupby("structure")["fitness"].mean()
    per_structure = per_structure.sort_values(per_structure.columns[0], ascending=False)
    overrides = " ".join(settings.overrides) or "(none)"
    return "".join([
        "# Noise ceiling: fitness of the same structures under independent seeds\n\n",
        f"{int(table['n_structures'].max())} structures × {settings.seeds} seeds, "
        f"{settings.budget:,} env steps per training; overrides: `{overrides}`.\n\n",
        f"Command: `{summary['command']}`\n\n",
        f"{summary['trainings']} trainings, {summary['env_steps']:,} env steps in "
        f"{summary['wall_seconds']:,.0f} s wall ({summary['steps_per_second']:,.0f} env "
        "steps/s over all workers).\n\n",
        "## Agreement between seeds\n\n",
        "Bootstrap 95 % CIs over structures. `spearman`, `kendall`, `top_quarter`: mean over "
        "seed pairs; `icc`: ICC(1), the share of fitness variance due to structure; "
        "`clears_baseline`: share of structures whose mean fitness beats the random "
        f"learner's on the same structure by more than {CLEAR_MARGIN:g}.\n\n",
        markdown_table(cells),
        "\nEstimators:\n\n", *[f"- `{k}`: {v}\n" for k, v in ESTIMATORS.items()],
        "\n## Fitness per structure (Eq. 8)\n\n",
        markdown_table(per_structure, index=True),
        "\n![fitness under one seed against another](noise_ceiling.png)\n",
    ])


def _shown(settings: RetrainSettings) -> dict[str, object]:
    """The settings as ``summary.json`` shows them: without the resolved config, and
    without the keys added since that keep their defaults (a noise ceiling's settings)."""
    shown: dict[str, object] = {**settings.record(), "config": None}
    defaults = RetrainSettings((), 0, 0, 0, False, (), "")
    for key in ("first_seed", "evaluate", "confirm", "labels"):
        if shown[key] == getattr(defaults, key):
            shown.pop(key)
    return shown


# ---------------------------------------------------------------- a folder's report


def report_folder(out: Path, *, command: str | None = None, resamples: int = 2000,
                  replicates: int = 2) -> Summary:
    """Write the report of the retraining folder ``out`` from its trainings.

    Args:
        out: The folder (``hydra.run.dir`` of ``+exp=retrain``).
        command: The command, as ``summary.json`` and the report name it; by default the
            retrain task's with the folder's overrides.
        resamples: Bootstrap resamples of the intervals.
        replicates: Finished trainings a structure needs to count.

    Raises:
        NoiseCeilingError: For a folder that holds no retraining.
        TooFewTrainings: When fewer than 3 structures have ``replicates`` finished
            trainings (run the retraining again to retry the failed ones).
    """
    layout = RetrainLayout(out)
    try:
        settings = read_retrain_settings(layout.settings)
    except ValueError as err:
        raise NoiseCeilingError(str(err)) from None
    if settings is None:
        raise NoiseCeilingError(f"{out}: no {layout.settings.name}; is it the folder of "
                                "python evo/main.py +exp=retrain?")
    trainings = read_trainings(layout.trainings)
    finished = by_role(trainings)[0].groupby("structure").size()
    if (finished >= replicates).sum() < 3:
        raise TooFewTrainings(f"{out}: fewer than 3 structures have {replicates} finished "
                              "trainings; run the same command again")
    if command is None:
        command = "python evo/main.py " + " ".join(settings.overrides)
    return write_report(out, trainings, settings, wall_seconds=read_progress(layout.progress),
                        command=command, resampling=Resampling.seeded(0, resamples))


# ---------------------------------------------------------------- CLI

FLAGS = {"retrain.robots": "--robots", "retrain.random": "--random",
         "retrain.seeds": "--seeds", "retrain.budget": "--budget", "hydra.run.dir": "--out"}
"""The older command line's name of each key that a message may name."""


def _as_flags(message: str) -> str:
    """``message`` with the keys of :data:`FLAGS` named as the command line names them."""
    for key, flag in FLAGS.items():
        message = message.replace(key, flag)
    return message


def parse_args(argv: Sequence[str]) -> argparse.Namespace:
    """The command line: a folder to report on, or the older one-shot options."""
    if not any(a.partition("=")[0] in ("--robots", "--random") for a in argv):
        report = argparse.ArgumentParser(
            prog="python -m analysis.noise_ceiling",
            description="The noise ceiling of a retraining's folder (python evo/main.py "
                        "+exp=retrain): how well one seed's fitness ranks the structures "
                        "as another's does. With --robots or --random instead: run the "
                        "retraining first (the older command line).")
        report.add_argument("folder", type=Path, help="the retraining's folder")
        report.add_argument("--resamples", type=int, default=2000, help="bootstrap resamples")
        args = report.parse_args(argv)
        args.out = None
    else:
        cli = argparse.ArgumentParser(
            prog="python -m analysis.noise_ceiling",
            description="Train structures under independent seeds (the retrain task of "
                        "evo/main.py: python evo/main.py +exp=retrain ...) and report how "
                        "well one seed's fitness ranks them as another's does.")
        source = cli.add_mutually_exclusive_group(required=True)
        source.add_argument("--robots", type=Path, help="folder of evo.robot/1 files")
        source.add_argument("--random", type=int, metavar="N", help="N random robots")
        cli.add_argument("--seed", type=int, default=0,
                         help="seed of the random robots and root of the training seeds")
        cli.add_argument("--seeds", type=int, default=2, metavar="K",
                         help="trainings per structure, each with its own seed (>= 2)")
        cli.add_argument("--budget", type=int, default=None,
                         help="env steps per training (default: learner.total_steps)")
        cli.add_argument("--no-baseline", action="store_true",
                         help="skip the random learner's training of each structure")
        cli.add_argument("--out", type=Path, required=True, help="output folder")
        cli.add_argument("--resamples", type=int, default=2000, help="bootstrap resamples")
        cli.add_argument("overrides", nargs="*",
                         help="config overrides as for python evo/main.py (learner.num_envs=32)")
        args = cli.parse_args(argv)
        args.folder = None
    if args.resamples < 1:
        print(f"error: --resamples: expected at least 1, got {args.resamples}",
              file=sys.stderr)
        sys.exit(2)
    return args


def retrain_overrides(args: argparse.Namespace) -> list[str]:
    """The retrain task's command line that the older options stand for."""
    source = (f"retrain.robots={args.robots}" if args.robots is not None
              else f"retrain.random={args.random}")
    return ["+exp=retrain", source, f"seed={args.seed}", f"retrain.seeds={args.seeds}",
            *([f"retrain.budget={args.budget}"] if args.budget is not None else []),
            *(["retrain.baseline=false"] if args.no_baseline else []),
            f"hydra.run.dir={args.out}", *args.overrides]


def main(argv: Sequence[str] | None = None) -> int:
    """Report on a folder, or (the older command line) run the retrain task and then
    report; exit 0, 2 with one line naming a bad argument, config key or a folder in
    use, 1 when too few trainings finished, the task's 130 or 143 when stopped."""
    given = sys.argv[1:] if argv is None else list(argv)
    args = parse_args(given)
    command: str | None = "python -m analysis.noise_ceiling " + shlex.join(given)
    out = args.folder
    if out is None:
        status = run_evo(retrain_overrides(args), rename=_as_flags)
        if status != 0:
            return status
        out = args.out
    else:
        command = None
    try:
        report_folder(out, command=command, resamples=args.resamples)
    except NoiseCeilingError as err:
        print(f"error: {err}", file=sys.stderr)
        return 1 if isinstance(err, TooFewTrainings) else 2
    print(f"report: {RetrainLayout(out).report}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
