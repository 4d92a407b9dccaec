"""The noise ceiling: how much of a structure's fitness is the structure, not the seed.

Fitness is the GA's only signal (SPEC §10). Train every structure of a sample K ≥ 2
times with independent seeds under one config, and ask how well one training ranks
the structures as another does:

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

The trainings are ``evo.retrain``'s (the ``retrain`` task of ``evo/main.py``):

    python evo/main.py +exp=retrain noise_ceiling.random=24 noise_ceiling.budget=100000 \
        hydra.run.dir=runs/noise [overrides...]

``python -m analysis.noise_ceiling --robots DIR | --random N --seed S [--seeds K]
--out DIR [--budget B] [--no-baseline] [--resamples R] [overrides...]`` is the same
task under its older command line: ``--out`` is the run directory, the other options
are the ``noise_ceiling`` keys (``--seed`` the root seed), and the overrides compose
the config exactly as ``python evo/main.py <overrides>`` composes it. Either way the
trainings run through the config's executor (both cores locally, a cluster with
``executor=ray``) and resume: run it again with the same arguments and finished
trainings are reused. This module turns them into ``noise_ceiling.md``,
``noise_ceiling.csv`` (the metrics), ``noise_ceiling.png`` (fitness under one seed
against another, one point per structure) and ``summary.json`` (settings, command,
env steps, wall time, metrics), beside ``trainings.csv`` (one row per training),
``robots/`` and ``evals/`` (each training's learning curve and policy, and recordings
if ``record`` asks for them).
"""

from __future__ import annotations

import argparse
import itertools
import json
import shlex
import sys
import warnings
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, TypedDict

import numpy as np
import pandas as pd
import scipy.stats
from numpy.typing import ArrayLike, NDArray

from analysis.markdown import fmt_ci, markdown_table
from analysis.stats import Resampling, Statistic, bootstrap_ci, kendall, spearman, top_recall
from analysis.tables import require_columns
from evo.retrain import RetrainConfig, RetrainError, Retraining, Settings, wall_seconds
from evo.run import layout as files
from evo.run.layout import RetrainLayout

if TYPE_CHECKING:
    from omegaconf import DictConfig

ESTIMATORS: dict[str, str] = {
    "fitness": "Eq. 8: mean return of every episode completed in training",
    "fitness_late": "mean return of the episodes completed in the second half of the budget",
}
METRICS: tuple[str, ...] = ("spearman", "kendall", "icc", "top_quarter", "clears_baseline")
TOP_SHARE = 0.25
"""Top-quarter agreement compares each seed's top 25 %."""
CLEAR_MARGIN = 0.01
"""Fitness by which a structure must beat the random learner to count as learning: a
hundredth of the time penalty's range, well above the float noise of a robot that
cannot move (its fitness is −1 to about 1e-6)."""
REPORT, SETTINGS, TRAININGS = files.CEILING_REPORT, files.RETRAIN_SETTINGS, files.TRAININGS
"""The report's, the settings' and the trainings' file names (``evo.run.layout``)."""
NoiseCeilingError = RetrainError
"""A bad argument or output folder; the message names it."""


class TooFewTrainings(RetrainError):
    """Fewer than 3 structures have two finished trainings: no rank correlation yet."""



class Summary(TypedDict):
    """``summary.json`` of a noise-ceiling folder."""

    settings: dict[str, object]  # Settings.to_json() without the resolved config
    command: str
    trainings: int
    env_steps: int
    wall_seconds: float
    training_seconds: float
    steps_per_second: float
    metrics: dict[str, dict[str, float]]  # estimator -> metric (and CI bound) -> value


# ---------------------------------------------------------------- metrics


def icc(*columns: ArrayLike, axis: int = -1) -> Any:
    """ICC(1) of a one-way random-effects model: each column one seed, each row
    (along ``axis``) one structure.

    ``(MSB − MSW) / (MSB + (K − 1)·MSW)``, with MSB the between-structure and MSW the
    within-structure mean square: the share of fitness variance due to the structure
    (1 when seeds agree exactly, about 0 when structure explains nothing; it can dip
    below 0 by chance).
    """
    x = np.stack([np.moveaxis(np.asarray(c, dtype=float), axis, -1) for c in columns])
    k, n = x.shape[0], x.shape[-1]
    means = x.mean(axis=0)
    grand = means.mean(axis=-1, keepdims=True)
    msb = k * ((means - grand) ** 2).sum(axis=-1) / (n - 1)
    msw = ((x - means) ** 2).sum(axis=0).sum(axis=-1) / (n * (k - 1))
    with np.errstate(divide="ignore", invalid="ignore"):
        return (msb - msw) / (msb + (k - 1) * msw)


def top_quarter(a: ArrayLike, b: ArrayLike, axis: int = -1) -> Any:
    """Share of ``a``'s top quarter that is also in ``b``'s (ties broken by position)."""
    return top_recall(a, b, share=TOP_SHARE, axis=axis)


def _pairwise_mean(metric: Statistic, k: int) -> Statistic:
    """``metric`` of two seed columns, averaged over all pairs of ``k`` columns."""
    pairs = list(itertools.combinations(range(k), 2))

    def mean(*cols: NDArray[np.float64], axis: int = -1) -> Any:
        return np.mean([metric(cols[i], cols[j], axis=axis) for i, j in pairs], axis=0)

    return mean


def _clears(k: int) -> Statistic:
    """Share of rows whose mean over the first ``k`` columns exceeds the last column by
    more than :data:`CLEAR_MARGIN`."""

    def share(*cols: NDArray[np.float64], axis: int = -1) -> Any:
        mean = np.mean(np.stack(cols[:k]), axis=0)
        return np.mean(mean > cols[k] + CLEAR_MARGIN, axis=axis)

    return share


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
    wide = trainings.pivot_table(index=structure, columns=seed, values=value,
                                 aggfunc="mean").dropna()
    k = wide.shape[1]
    if k < 2:
        raise ValueError(f"noise ceiling needs at least two values of {seed!r}, got {k}")
    columns = [wide[c].to_numpy(dtype=float) for c in wide.columns]
    statistics: dict[str, Statistic] = {
        "spearman": _pairwise_mean(spearman, k), "kendall": _pairwise_mean(kendall, k),
        "icc": icc, "top_quarter": _pairwise_mean(top_quarter, k),
    }
    out: dict[str, float] = {}
    for name, statistic in statistics.items():
        out.update(_with_ci(name, columns, statistic, resampling))
    base = None if baseline is None else baseline.reindex(wide.index).to_numpy(dtype=float)
    if base is None or not np.isfinite(base).all():
        out.update(clears_baseline=np.nan, clears_baseline_low=np.nan,
                   clears_baseline_high=np.nan)
    else:
        out.update(_with_ci("clears_baseline", [*columns, base], _clears(k), resampling))
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
    seeds, base = _by_role(trainings)
    rows = []
    for estimator in ESTIMATORS:
        baseline = base.groupby("structure")[estimator].mean() if len(base) else None
        ceiling = noise_ceiling(seeds, resampling, seed="replicate", value=estimator,
                                baseline=baseline)
        rows.append(dict(estimator=estimator, **ceiling))
    return pd.DataFrame(rows)


def _by_role(trainings: pd.DataFrame) -> tuple[pd.DataFrame, pd.DataFrame]:
    """The seed trainings and the baseline trainings."""
    return (trainings[trainings["role"] == "seed"], trainings[trainings["role"] == "baseline"])


# ---------------------------------------------------------------- report


def write_report(out: Path, trainings: pd.DataFrame, settings: Settings, *,
                 wall_seconds: float, command: str, resampling: Resampling | None = None
                 ) -> Summary:
    """``noise_ceiling.md``, ``.csv``, ``.png`` and ``summary.json`` from the trainings;
    returns what ``summary.json`` holds (:func:`read_summary` reads it back)."""
    from analysis.plots import plot_seed_scatter

    table = ceiling_table(trainings, resampling or Resampling.seeded(0))
    layout = RetrainLayout(out)
    table.to_csv(layout.metrics, index=False)
    seeds, base = _by_role(trainings)
    plot_seed_scatter(seeds, base, estimators=list(ESTIMATORS), ceiling=table,
                      margin=CLEAR_MARGIN, path=layout.figure)
    steps = int(trainings["env_steps"].sum())
    summary = Summary(
        settings=settings.to_json() | {"config": None}, command=command,
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


def _markdown(table: pd.DataFrame, trainings: pd.DataFrame, settings: Settings,
              summary: Summary) -> str:
    cells = pd.DataFrame({
        "estimator": table["estimator"],
        **{metric: [fmt_ci(r[metric], r[f"{metric}_low"], r[f"{metric}_high"])
                    for r in table.to_dict("records")] for metric in METRICS},
        "structures": table["n_structures"].astype(int),
    })
    seeds, base = _by_role(trainings)
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


# ---------------------------------------------------------------- CLI


def run(cfg: DictConfig, out: Path, config: RetrainConfig, *, root_seed: int,
        overrides: Sequence[str], command: str,
        on_ready: Callable[[], None] | None = None) -> Path:
    """The noise ceiling of ``config``'s structures under ``cfg``: their trainings
    (``evo.retrain``, resumed in ``out``), then the report.

    Args:
        cfg: The composed config (its learner, env, physics, executor, ...).
        out: The run directory.
        config: The ``noise_ceiling`` settings.
        root_seed: Seed of the random robots and root of the training seeds.
        overrides: The config overrides, as ``settings.json`` and the report name them.
        command: The command, as ``summary.json`` and the report name it.
        on_ready: Called once the settings and the folder are checked, before anything
            trains (the run directory's ``RunLock.claim``).

    Returns:
        The report, ``noise_ceiling.md``.

    Raises:
        NoiseCeilingError: For a bad setting or folder.
        TooFewTrainings: When fewer than 3 structures have two finished trainings (run
            it again to retry the failed ones).
        evo.config.ConfigError: For a config that cannot train (its key named).
    """
    from evo.edge import retraining

    retrain = retraining(cfg, out, config, root_seed=root_seed, overrides=overrides)
    if on_ready is not None:
        on_ready()
    report_trainings(cfg, out, retrain, replicates=2, command=command,
                     resamples=config.resamples, too_few=lambda: TooFewTrainings(
                         f"{out}: fewer than 3 structures have two finished trainings; "
                         "run the same command again"))
    return RetrainLayout(out).report


def report_trainings(cfg: DictConfig, out: Path, retrain: Retraining, *, replicates: int,
                     command: str, resamples: int, too_few: Callable[[], Exception]
                     ) -> tuple[pd.DataFrame, Summary]:
    """Run (or resume) ``retrain``'s trainings through ``cfg``'s executor, then write the
    report of ``out``.

    Args:
        cfg: The composed config (its executor).
        out: The run directory.
        retrain: The trainings (``evo.edge.retraining``).
        replicates: Finished trainings a structure needs to count; at least 3 such
            structures, or ``too_few()`` is raised.
        command: The command, as ``summary.json`` and the report name it.
        resamples: Bootstrap resamples of the report's intervals.
        too_few: The error for too few finished structures.

    Returns:
        The trainings, and what ``summary.json`` holds.
    """
    from evo.edge import executor_of
    from evo.pool import EvaluationPool
    from evo.retrain import run_trainings

    trainings = run_trainings(retrain, EvaluationPool(executor_of(cfg)))
    finished = _by_role(trainings)[0].groupby("structure").size()
    if (finished >= replicates).sum() < 3:
        raise too_few()
    summary = write_report(out, trainings, retrain.settings, wall_seconds=wall_seconds(out),
                           command=command,
                           resampling=Resampling.seeded(0, resamples))
    return trainings, summary


# ---------------------------------------------------------------- the older command line

FLAGS = {"noise_ceiling.robots": "--robots", "noise_ceiling.random": "--random",
         "noise_ceiling.seeds": "--seeds", "noise_ceiling.budget": "--budget",
         "noise_ceiling.resamples": "--resamples", "hydra.run.dir": "--out"}
"""The command line's name of each key that a message may name."""


def _as_flags(message: str) -> str:
    """``message`` with the keys of :data:`FLAGS` named as the command line names them."""
    for key, flag in FLAGS.items():
        message = message.replace(key, flag)
    return message


def parse_args(argv: Sequence[str] | None) -> argparse.Namespace:
    cli = argparse.ArgumentParser(
        prog="python -m analysis.noise_ceiling",
        description="Train structures under independent seeds and measure how well one "
                    "seed's fitness ranks them as another's does (the retrain task of "
                    "evo/main.py: python evo/main.py +exp=retrain ...).")
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
    return cli.parse_args(argv)


def _config_of(args: argparse.Namespace) -> RetrainConfig:
    """The ``noise_ceiling`` settings the arguments give (checked)."""
    from evo.config import typed

    return typed(RetrainConfig, {
        "robots": None if args.robots is None else str(args.robots), "random": args.random,
        "seeds": args.seeds, "budget": args.budget, "baseline": not args.no_baseline,
        "resamples": args.resamples}, "noise_ceiling")


def main(argv: Sequence[str] | None = None) -> int:
    """Run the retrain task under the older command line, in ``--out`` (its lock held,
    SIGINT and SIGTERM stopping the trainings at once); exit 0, 2 with one line naming
    a bad argument or config key or a folder in use, 1 when too few trainings finished,
    130 or 143 when stopped."""
    from evo.config import ConfigError
    from evo.edge import compose_config
    from evo.interrupt import Interrupted, handle_signals
    from evo.run.files import RunDirectoryBusy, RunLock

    args = parse_args(argv)
    command = "python -m analysis.noise_ceiling " + shlex.join(
        sys.argv[1:] if argv is None else list(argv))
    try:
        config = _config_of(args)
        cfg = compose_config(args.overrides)
        if args.out.exists() and not args.out.is_dir():
            raise NoiseCeilingError(f"hydra.run.dir {args.out}: exists and is not a folder")
        args.out.mkdir(parents=True, exist_ok=True)
        with handle_signals(), RunLock(args.out) as lock:
            report = run(cfg, args.out, config, root_seed=args.seed, overrides=args.overrides,
                         command=command, on_ready=lock.claim)
    except (NoiseCeilingError, ConfigError, RunDirectoryBusy) as err:
        print(f"error: {_as_flags(str(err))}", file=sys.stderr)
        return 1 if isinstance(err, TooFewTrainings) else 2
    except Interrupted as stop:
        print(f"interrupted; {args.out} is incomplete: run the same command again to "
              "continue it", file=sys.stderr)
        return stop.exit_code
    print(f"report: {report}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
