"""The early-slope study report: ``python -m analysis.early_slope RUN... --out DIR`` (or
``python -m analysis early_slope ...``).

Does the start of a learning curve predict a robot's fitness (paper §8, §9)? This
module runs :mod:`analysis.early_slope` on loaded runs (the study's one computation,
:func:`early_slope_study`) and writes ``DIR/early_slope.md`` with PNG figures beside it
(:func:`write_early_slope_report`):

* Spearman ρ and Kendall τ of each predictor (value, slope, area, fitted curve,
  value+slope) with the final fitness and with the return after the cut, per cut, each
  with a bootstrap CI;
* top-10 % recall per cut and predictor;
* early rejection: env steps saved against good robots and best fitness lost, for
  rejecting the lowest quarter of predictions and for rejecting predictions below the
  population minimum the robot had to beat;
* the noise ceiling (the rank agreement of the same structures trained again), when
  ``--retrained DIR...`` gives such trainings (:func:`analysis.load.load_retrained`);
  reported as absent otherwise.

**Robots studied (decision).** Learning curves say something about learning only when
the behaviour is learned, so by default the study takes the robots of the learned
methods (``R+L``, ``E+L``); with none in the input it takes every robot and says so.
``--methods`` chooses. Robots without a fitness are left out.
"""

from __future__ import annotations

import sys
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd
from matplotlib.figure import Figure

from analysis import early_slope as es
from analysis import plots
from analysis.cli import parser, report_folder, resampling_of, run_report
from analysis.load import RunDirectoryError, Runs, load_retrained, load_runs
from analysis.markdown import figure_link, fmt_ci, markdown_table
from analysis.noise_ceiling import noise_ceiling
from analysis.stats import Resampling
from analysis.tables import fully_trained, method_order

REPORT = "early_slope.md"
SCATTER_FRACTION = 0.2
"""The cut of the scatter figure: the paper compares rankings at 30k of 150k steps."""


@dataclass
class EarlySlopeStudy:
    """Every table of the early-slope study.

    Attributes:
        methods: The methods whose robots were studied.
        robots: Number of robots studied.
        table: :func:`analysis.early_slope.early_table`.
        preds: :func:`analysis.early_slope.predictions` for both targets.
        metrics: :func:`analysis.early_slope.rank_metrics`.
        rejection: :func:`analysis.early_slope.rejection_tradeoff`, quantile rule,
            predicting fitness.
        rejection_population: The same with the population-minimum rule.
        ceiling: :func:`analysis.noise_ceiling.noise_ceiling`, or None without retraining.
        notes: Sentences on the input and what was left out.
    """

    methods: list[str]
    robots: int
    table: pd.DataFrame
    preds: pd.DataFrame
    metrics: pd.DataFrame
    rejection: pd.DataFrame
    rejection_population: pd.DataFrame
    ceiling: pd.Series | None
    notes: list[str] = field(default_factory=list)


def study_robots(robots: pd.DataFrame,
                 methods: Sequence[str] | None = None) -> tuple[pd.DataFrame, list[str], str]:
    """The robots the study takes (see the module docstring).

    Returns:
        The robots, their methods and a note saying which were taken.
    """
    scored = fully_trained(robots)
    present = method_order(scored["method"])
    if methods is not None:
        chosen = [m for m in method_order(methods) if m in present]
        note = f"Methods asked for: {', '.join(methods)}; present: {', '.join(chosen) or 'none'}."
    else:
        chosen = [m for m in present if m.endswith("+L")]
        note = f"Robots of the learned methods: {', '.join(chosen)}."
        if not chosen:
            chosen = present
            note = ("No learned method (R+L, E+L) in the input: every robot is studied, "
                    "though random-policy curves carry no learning signal.")
    stopped = int((robots["status"] == "stopped-early").sum()) if "status" in robots else 0
    if stopped:
        note += (f" {stopped} robot(s) stopped early by early rejection left out: their "
                 "curves end before the cuts a prediction is scored against.")
    return scored[scored["method"].isin(chosen)], chosen, note


def early_slope_study(
    robots: pd.DataFrame,
    curves: pd.DataFrame,
    resampling: Resampling,
    *,
    methods: Sequence[str] | None = None,
    fractions: Sequence[float] = es.FRACTIONS,
    population_size: int | Mapping[str, int] = 20,
    quantile: float = 0.25,
    share: float = 0.1,
    top_k: int | None = None,
    retrained: pd.DataFrame | None = None,
) -> EarlySlopeStudy:
    """Run the early-slope analysis on loaded runs.

    Args:
        robots: Robots table.
        curves: Curves table.
        resampling: How the intervals are drawn.
        methods: Methods to study; None for the learned ones (module docstring).
        fractions: Cuts, as fractions of each robot's budget.
        population_size: Initial population size, one for all runs or per run id.
        quantile: Share of robots the quantile rejection rule rejects.
        share: Top share for the recall (0.1: top 10 %).
        top_k: Size of the top whose losses the rejection counts; None for the top
            ``share`` of the robots studied.
        retrained: :func:`analysis.load.load_retrained`, or None.

    Returns:
        The study's tables.

    Raises:
        ValueError: If no robot with a fitness is left to study.
    """
    chosen, studied, note = study_robots(robots, methods)
    if chosen.empty:
        raise ValueError(f"no robot with a fitness to study (methods {methods or 'learned'})")
    notes = [note]
    table = _early_table(chosen, curves, fractions, population_size)
    no_curve = int(table.groupby(["run", "name"])["value"].apply(lambda v: v.isna().all()).sum())
    if no_curve:
        notes.append(f"{no_curve} robot(s) have no informative batch before any cut "
                     "(no episode completed early); they count as missing predictions.")
    preds = pd.concat([es.predictions(table, target) for target in es.TARGETS],
                      ignore_index=True)
    metrics = es.rank_metrics(preds, resampling, share=share)
    k = top_k or max(1, int(np.ceil(share * len(chosen))))
    fitness_preds = preds[preds["target"] == "fitness"]
    rejection = es.rejection_tradeoff(fitness_preds, quantile=quantile, top_k=k)
    population = es.rejection_tradeoff(fitness_preds, threshold_column="threshold", top_k=k)
    ceiling, note = (noise_ceiling_of(chosen, retrained, resampling)
                     if retrained is not None else
                     (None, "Noise ceiling: absent (no retrained structures given; "
                            "--retrained DIR...)."))
    notes.append(note)
    return EarlySlopeStudy(methods=studied, robots=len(chosen), table=table, preds=preds,
                           metrics=metrics, rejection=rejection,
                           rejection_population=population, ceiling=ceiling, notes=notes)


def _early_table(chosen: pd.DataFrame, curves: pd.DataFrame, fractions: Sequence[float],
                 population_size: int | Mapping[str, int]) -> pd.DataFrame:
    """``early_slope.early_table`` of every run, each with its own population size."""
    sizes = (population_size if isinstance(population_size, Mapping)
             else dict.fromkeys(chosen["run"].unique(), population_size))
    return pd.concat([
        es.early_table(rows, curves[curves["run"].isin(rows["run"].unique())], fractions,
                       population_size=size)
        for size, rows in chosen.groupby(chosen["run"].map(sizes))
    ], ignore_index=True)


def noise_ceiling_of(robots: pd.DataFrame, retrained: pd.DataFrame, resampling: Resampling
                     ) -> tuple[pd.Series | None, str]:
    """The noise ceiling from retrained structures and their first training in the runs.

    A structure's evaluation in the runs counts as one more training seed
    (``"original"``) beside its retrainings.

    Returns:
        :func:`analysis.noise_ceiling.noise_ceiling` (None when it cannot be computed)
        and a sentence about it.
    """
    structures = set(retrained["structure"])
    original = robots.assign(structure=robots["name"].str.slice(0, len("robot-") + 8))
    original = original[original["structure"].isin(structures)]
    rows = pd.concat([
        retrained[["structure", "train_seed", "fitness"]].astype({"train_seed": str}),
        original[["structure", "fitness"]].drop_duplicates("structure")
        .assign(train_seed="original"),
    ], ignore_index=True)
    try:
        ceiling = noise_ceiling(rows, resampling)
    except ValueError as err:
        return None, f"Noise ceiling: not computed ({err})."
    return ceiling, (f"Noise ceiling from {int(ceiling['n_structures'])} structures trained "
                     f"with {int(ceiling['n_seeds'])} seeds.")


# ---------------------------------------------------------------- tables for reading


def correlation_table(metrics: pd.DataFrame, target: str) -> pd.DataFrame:
    """Per cut and predictor: Spearman and Kendall as ``estimate [CI]``, and n."""
    rows = metrics[(metrics["target"] == target) & metrics["metric"].isin(["spearman",
                                                                             "kendall"])]
    cells = rows.assign(cell=[fmt_ci(r.estimate, r.ci_low, r.ci_high)
                              for r in rows.itertuples()])
    wide = cells.pivot_table(index=["fraction", "predictor"], columns="metric", values="cell",
                             aggfunc="first", sort=False).reset_index()
    n = rows.groupby(["fraction", "predictor"], sort=False)["n"].first().reset_index()
    wide = wide.merge(n, on=["fraction", "predictor"])
    return wide[["fraction", "predictor", "spearman", "kendall", "n"]]


def recall_table(metrics: pd.DataFrame, target: str = "fitness") -> pd.DataFrame:
    """Top recall as ``estimate [CI]``: one row per cut, one column per predictor."""
    rows = metrics[(metrics["target"] == target) & (metrics["metric"] == "top_recall")]
    cells = rows.assign(cell=[fmt_ci(r.estimate, r.ci_low, r.ci_high, digits=2)
                              for r in rows.itertuples()])
    wide = cells.pivot_table(index="fraction", columns="predictor", values="cell",
                             aggfunc="first", sort=False)
    return wide[[p for p in es.PREDICTORS if p in wide.columns]].reset_index()


REJECTION_COLUMNS = ["fraction", "predictor", "n", "rejected", "saved_share", "top_k_lost",
                     "best_lost", "best_kept", "fitness_lost"]


# ---------------------------------------------------------------- figures and Markdown


def early_slope_figures(study: EarlySlopeStudy,
                        out: str | Path | None = None) -> dict[str, Figure]:
    """The study's figures, written as ``out/<key>.png`` when ``out`` is given.

    Returns:
        File stem → figure: ``rank_<target>`` per target, ``rejection_quantile``,
        ``rejection_population`` and ``scatter`` (predictions at the cut nearest
        :data:`SCATTER_FRACTION`).
    """
    folder = None if out is None else Path(out)

    def path(stem: str) -> Path | None:
        return None if folder is None else folder / f"{stem}.png"

    ceiling = None if study.ceiling is None else float(study.ceiling["spearman"])
    figures = {f"rank_{t}": plots.plot_rank_metrics(study.metrics, t, ceiling=ceiling,
                                                    path=path(f"rank_{t}"))
               for t in es.TARGETS}
    figures["rejection_quantile"] = plots.plot_rejection_tradeoff(
        study.rejection, title="reject the lowest quarter of predictions",
        path=path("rejection_quantile"))
    figures["rejection_population"] = plots.plot_rejection_tradeoff(
        study.rejection_population, title="reject below the population minimum",
        path=path("rejection_population"))
    fractions = np.asarray(sorted(study.table["fraction"].unique()))
    cut = float(fractions[np.argmin(np.abs(fractions - SCATTER_FRACTION))])
    figures["scatter"] = plots.plot_early_scatter(
        study.preds[study.preds["target"] == "fitness"], cut, path=path("scatter"))
    return figures


def early_slope_markdown(runs: Runs, study: EarlySlopeStudy, figures: dict[str, Path],
                         out: Path) -> str:
    """The report's Markdown text (links relative to the report folder ``out``)."""
    s = study
    parts = ["# Early-slope study: does the start of a learning curve predict fitness?\n\n",
             f"{s.robots} robots of {', '.join(s.methods)} from {len(runs.runs)} run(s); "
             f"cuts at {', '.join(f'{f:g}' for f in sorted(s.table['fraction'].unique()))} "
             "of each robot's budget.\n\n"]
    parts += [f"- {note}\n" for note in [*runs.notes, *s.notes]]
    parts += ["\n## Runs\n\n", markdown_table(runs.runs.drop(columns="path"))]
    parts += ["\n## Noise ceiling\n\n", _ceiling_markdown(s.ceiling)]
    for target in es.TARGETS:
        what = ("final fitness (the whole training's mean return, prefix included)"
                if target == "fitness" else "mean return after the cut (unseen at the cut)")
        parts += [f"\n## Rank correlation with the {what}\n\n",
                  "Bootstrap 95 % CIs; n robots with a prediction.\n\n",
                  markdown_table(correlation_table(s.metrics, target))]
    parts += ["\n## Top-10 % recall (final fitness)\n\n",
              "Share of the actual top 10 % that each predictor also puts in its top 10 %.\n\n",
              markdown_table(recall_table(s.metrics, "fitness"), digits=2)]
    for title, table in (("reject the lowest quarter of predictions", s.rejection),
                         ("reject below the population minimum", s.rejection_population)):
        parts += [f"\n## Early rejection: {title}\n\n",
                  "Offline estimate: the rest of each run kept as it happened. "
                  "`top_k_lost`: robots of the final top k (k = top 10 %) rejected; "
                  "`fitness_lost`: best fitness minus the best kept.\n\n",
                  markdown_table(table[REJECTION_COLUMNS])]
    parts.append("\n## Figures\n")
    for stem, path in figures.items():
        parts.append(f"\n### {stem}\n\n" + figure_link(path, out, stem))
    return "".join(parts)


def _ceiling_markdown(ceiling: pd.Series | None) -> str:
    if ceiling is None:
        return ("Absent: no retrained structures were given (`--retrained DIR...`), so "
                "there is no bound on what a predictor can reach.\n")
    return (f"Spearman ρ between trainings of the same structures: "
            f"{_metric_ci(ceiling, 'spearman')} "
            f"({int(ceiling['n_structures'])} structures, {int(ceiling['n_seeds'])} seeds); "
            f"ICC {_metric_ci(ceiling, 'icc')}; top-quarter agreement "
            f"{_metric_ci(ceiling, 'top_quarter')} (`python -m analysis.noise_ceiling`).\n")


def _metric_ci(ceiling: pd.Series, metric: str) -> str:
    return fmt_ci(ceiling[metric], ceiling[f"{metric}_low"], ceiling[f"{metric}_high"])


# ---------------------------------------------------------------- CLI


def write_early_slope_report(
    runs: Runs,
    out: str | Path,
    *,
    retrained: Sequence[str | Path] | None = None,
    methods: Sequence[str] | None = None,
    fractions: Sequence[float] = es.FRACTIONS,
    resampling: Resampling | None = None,
) -> Path:
    """Run the study, draw its figures and write ``out/early_slope.md``.

    Args:
        runs: The runs, as :func:`analysis.load.load_runs` read them.
        out: Report folder (created).
        retrained: Directories of retrained structures, or None.
        methods: Methods to study; None for the learned ones.
        fractions: Cuts, as fractions of each robot's budget.
        resampling: How the intervals are drawn; None for seed 0 and 2000 resamples.

    Returns:
        The path of the Markdown report (``rank_metrics.csv`` and ``rejection.csv``
        beside it).
    """
    if study_robots(runs.robots, methods)[0].empty:
        raise RunDirectoryError(
            f"{runs.where}: no robot with a fitness of the methods "
            f"{', '.join(methods) if methods else 'R+L, E+L'} to study")
    out = report_folder(out)
    study = early_slope_study(
        runs.robots, runs.curves, resampling or Resampling.seeded(0), methods=methods,
        fractions=fractions, population_size=runs.population_sizes,
        retrained=None if not retrained else load_retrained(retrained))
    figures = early_slope_figures(study, out)
    report = out / REPORT
    written = {stem: out / f"{stem}.png" for stem in figures}
    report.write_text(early_slope_markdown(runs, study, written, out), encoding="utf-8")
    study.metrics.to_csv(out / "rank_metrics.csv", index=False)
    pd.concat([study.rejection.assign(rule="quantile"),
               study.rejection_population.assign(rule="population_min")]
              ).to_csv(out / "rejection.csv", index=False)
    return report


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m analysis.early_slope RUN... --out DIR``; exit 0, or 2 on a bad input."""
    cli = parser("Early-slope study (paper sections 8-9) of evo runs.",
                 prog="python -m analysis.early_slope")
    cli.add_argument("--retrained", nargs="+", type=Path, default=None,
                     help="directories of structures trained again (noise ceiling)")
    cli.add_argument("--methods", nargs="+", default=None,
                     help="methods to study (default: the learned ones, R+L and E+L)")
    cli.add_argument("--fractions", nargs="+", type=float, default=list(es.FRACTIONS),
                     help="cuts as fractions of each robot's budget")
    args = cli.parse_args(argv)
    outside = [f for f in args.fractions if not 0 < f < 1]
    if outside:
        print(f"error: --fractions: cuts are fractions of a budget, between 0 and 1 "
              f"(exclusive); got {', '.join(f'{f:g}' for f in outside)}", file=sys.stderr)
        return 2
    return run_report(lambda: write_early_slope_report(
        load_runs(args.runs, args.first), args.out, retrained=args.retrained, methods=args.methods,
        fractions=args.fractions, resampling=resampling_of(args)))
