"""The ablation report (paper §8): ``python -m analysis.report RUN... --out DIR`` (or
``python -m analysis ablation ...``).

The study's one computation is :func:`ablation_tables` (every table, from a robots
table), its writer :func:`write_report` and its command line :func:`main`. It reads run
directories (or a Hydra multirun folder, :func:`analysis.load.load_runs`; with
``--history-only`` their committed ``history.csv`` and ``summary.json`` alone,
:func:`analysis.load.load_histories`, and no learning-curve figures) and writes
``DIR/report.md`` with its PNG figures beside it:

* per method: n, max, top-5 mean, mean, median, IQM and std of fitness, each with a
  bootstrap CI (:func:`analysis.ablation.robot_level.summarize`);
* the Kruskal–Wallis test, pairwise Mann–Whitney U tests with Holm's adjustment and
  Vargha–Delaney A12 (:mod:`analysis.ablation.robot_level`); with three or more GA seeds per
  method the same tests on per-run means;
* the interaction contrast ``(E+L − R+L) − (E+R − R+R)`` and its two parts, with CIs;
* with two or more GA seeds per method, the sections with the run as the unit
  (:mod:`analysis.ablation.nested_report`): per question, Welch's t-test on run means
  and a mixed model with a random intercept per run; per-run summaries; the GA seeds a
  run-level test needs (:mod:`analysis.ablation.power`);
* the paper's figures (:mod:`analysis.plots`): fitness per robot in birth order, each
  method against R+R (Figs. 13–15); every run's fitness over the evolution (Figs. 10,
  12); learning curves of selected robots (Figs. 9, 11); best fitness so far against
  cumulative env steps;
* the paper's numbers beside ours (the reward scales differ; see the report's note);
* a fifth arm, E+L+I (E+L with policy inheritance), when present: in the tables and
  figures, left out of the paper's tests, with a question of its own, E+L+I vs E+L
  (:data:`analysis.ablation.nested.EXTRA_PAIRS`: Mann–Whitney on robots here, Welch on run means
  and the mixed model in the run-level sections), outside the paper's Holm family.

Methods missing from the input are listed as missing; whatever needs them (a test, a
contrast, a panel) is left out with a sentence saying so. Robots whose evaluation
failed (no fitness) are left out of the statistics and counted.

The notebook (``analysis/ablation.pct.py``) calls the same functions (:func:`ablation_tables`,
:func:`ablation_figures`, :func:`ablation_markdown`), so the report and the notebook on the
same runs show the same numbers for the same ``--seed``.
"""

from __future__ import annotations

import sys
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import cast

import numpy as np
import pandas as pd
from matplotlib.figure import Figure

from analysis import plots
from analysis.ablation import robot_level
from analysis.ablation.nested import EXTRA_PAIRS, question_name
from analysis.ablation.nested_report import (
    NestedTables,
    nested_markdown,
    nested_tables,
    write_nested_tables,
)
from analysis.cli import parser, report_folder, resampling_of, run_report
from analysis.load import RunDirectoryError, Runs, load_histories, load_runs
from analysis.markdown import figure_link, fmt_ci, markdown_table, safe_name
from analysis.stats import Resampling
from analysis.tables import EXTRA_METHODS, METHODS, fully_trained, method_order, paper_rows

REPORT = "report.md"
LEARNING_CURVES = 8
"""Robots per learning-curve figure (the paper's Fig. 9 shows ten)."""
SEEDS_FOR_RUN_TESTS = 3
"""GA seeds each method needs before the report also tests per-run means."""


# ---------------------------------------------------------------- tables


@dataclass
class AblationTables:
    """Every table of the ablation report.

    Attributes:
        present: Methods with at least one robot with a fitness, in report order.
        missing: Of the four ablation methods, those with none.
        left_out: Robots without a fitness (failed evaluations), left out.
        summary: :func:`analysis.ablation.robot_level.summarize` (long).
        main: One row per ablation method (missing ones marked), statistics as
            ``estimate [ci_low, ci_high]``.
        kruskal: The Kruskal–Wallis test over robots, or None.
        pairwise: :func:`analysis.ablation.robot_level.pairwise_mann_whitney` over robots.
        extra_pairwise: The same for :data:`analysis.ablation.nested.EXTRA_PAIRS` whose methods
            are present, each its own test (empty without them).
        per_run: The same two tests on per-run means (``kruskal``, ``pairwise``), or
            None with too few seeds.
        interaction: :func:`analysis.ablation.robot_level.interaction_contrast`, or None.
        paper: :func:`analysis.ablation.robot_level.compare_with_paper`.
        budgets: Per method: median, min and max env steps per robot.
        notes: Sentences on what was left out and why.
        nested: The run-level sections (:mod:`analysis.ablation.nested_report`), or None with
            fewer than two GA seeds per method.
    """

    present: list[str]
    missing: list[str]
    left_out: int
    summary: pd.DataFrame
    main: pd.DataFrame
    kruskal: robot_level.GroupTest | None
    pairwise: pd.DataFrame
    per_run: tuple[robot_level.GroupTest | None, pd.DataFrame] | None
    interaction: pd.DataFrame | None
    paper: pd.DataFrame
    budgets: pd.DataFrame
    notes: list[str] = field(default_factory=list)
    nested: NestedTables | None = None
    extra_pairwise: pd.DataFrame = field(default_factory=pd.DataFrame)


EXTRA_NOTE = (
    "{methods}: beyond the paper's four methods, in the tables and figures but left out "
    "of the paper's tests (Kruskal–Wallis, the pairwise tests and their Holm family, the "
    "interaction, the order beside the paper); each answers its own question "
    "({questions}). E+L+I is E+L whose offspring start from a parent's trained policy "
    "(ga.inheritance): its fitness includes what its robots inherited, so it measures "
    "policy and body together, not the body alone."
)


def _input_notes(robots: pd.DataFrame, scored: pd.DataFrame,
                 missing: list[str]) -> tuple[list[str], int]:
    """What the input lacks (methods, fitnesses, whole budgets), and how many robots
    failed."""
    notes = []
    if missing:
        notes.append(f"Methods missing from the input: {', '.join(missing)}; the tests "
                     "and contrasts that need them are left out.")
    stopped = int((robots["status"] == "stopped-early").sum()) if "status" in robots else 0
    left_out = len(robots) - len(scored) - stopped
    if left_out:
        notes.append(f"{left_out} robot(s) without a fitness (failed evaluation) left out.")
    if stopped:
        notes.append(f"{stopped} robot(s) stopped early by early rejection left out of the "
                     "fitness statistics: their fitness covers only part of a budget.")
    return notes, left_out


def ablation_tables(robots: pd.DataFrame, resampling: Resampling, *, k: int = 5,
                    population_size: int = 20) -> AblationTables:
    """Summaries, tests, contrasts and the paper's numbers for a robots table.

    Args:
        robots: Robots table (any subset of the four methods).
        resampling: How the intervals are drawn (its generator also drives the power
            simulation, after every interval).
        k: ``k`` of the top-k mean.
        population_size: Initial population size (for the final population's mean).

    Returns:
        The tables; what cannot be computed is None and explained in ``notes``.

    Raises:
        ValueError: If no robot has a fitness.
    """
    scored = fully_trained(robots)
    if scored.empty:
        raise ValueError(f"no fully trained robot with a fitness among {len(robots)} robots")
    present = method_order(scored["method"])
    missing = [m for m in METHODS if m not in present]
    notes, left_out = _input_notes(robots, scored, missing)
    paper = paper_rows(scored)  # the paper's methods: their numbers as without the others
    extra_pairs = [(a, b) for a, b in EXTRA_PAIRS if {a, b} <= set(present)]
    if len(paper) < len(scored):
        notes.append(EXTRA_NOTE.format(
            methods=", ".join(m for m in present if m in EXTRA_METHODS),
            questions=", ".join(question_name(a, b) for a, b in extra_pairs)
            or "none here: a method it is compared with is missing"))
    summary = robot_level.summarize(paper, resampling, k=k)
    kruskal, pairwise = _tests(paper, None, notes)
    per_run = None
    runs_per_method = paper.groupby("method")["run"].nunique()
    if paper["method"].nunique() >= 2 and runs_per_method.min() >= SEEDS_FOR_RUN_TESTS:
        per_run = _tests(paper, "mean", notes)
    else:
        notes.append(f"Tests on per-run means need {SEEDS_FOR_RUN_TESTS} or more GA seeds "
                     "per method; the tests below compare robots.")
    interaction = None
    if not missing:
        interaction = robot_level.interaction_contrast(scored, resampling)
    else:
        notes.append("The interaction contrast needs all four methods; not computed.")
    nested = nested_tables(scored, population_size, resampling.rng)
    if nested is None:
        notes.append("Run-level statistics need two or more GA seeds per method; not "
                     "computed.")
    extra = scored[scored["method"].isin(EXTRA_METHODS)]
    if len(extra):  # last, so that the paper's intervals draw what they draw without it
        summary = pd.concat([summary, robot_level.summarize(extra, resampling, k=k)],
                            ignore_index=True)
    return AblationTables(
        present=present, missing=missing, left_out=left_out, summary=summary,
        main=main_table(summary, missing), kruskal=kruskal, pairwise=pairwise,
        per_run=per_run, interaction=interaction,
        paper=robot_level.compare_with_paper(summary), budgets=budget_table(scored), notes=notes,
        nested=nested, extra_pairwise=robot_level.pairwise_mann_whitney(scored, pairs=extra_pairs)
        if extra_pairs else pd.DataFrame(),
    )


def _tests(
    robots: pd.DataFrame, per_run: str | None, notes: list[str]
) -> tuple[robot_level.GroupTest | None, pd.DataFrame]:
    """Kruskal–Wallis and pairwise tests, or None and an empty table with a note."""
    unit = "per-run means" if per_run else "robots"
    if robots["method"].nunique() < 2:
        notes.append(f"Tests on {unit} need two methods or more; not computed.")
        return None, pd.DataFrame()
    try:
        kruskal = robot_level.kruskal_wallis(robots, per_run=per_run)
    except ValueError as err:  # scipy: all values identical
        notes.append(f"Kruskal–Wallis on {unit} not computed: {err}.")
        kruskal = None
    return kruskal, robot_level.pairwise_mann_whitney(robots, per_run=per_run)


def main_table(summary: pd.DataFrame, missing: Sequence[str] = ()) -> pd.DataFrame:
    """One row per method: n, seeds, resampling unit and every statistic with its CI.

    Args:
        summary: :func:`analysis.ablation.robot_level.summarize`.
        missing: Methods to list as missing (no robots).

    Returns:
        Columns ``method``, ``n``, ``seeds``, ``unit``, then one per statistic.
    """
    rows = []
    for method, group in summary.groupby("method", sort=False):
        row: dict[str, object] = dict(method=method, n=int(group["n"].iloc[0]),
                                      seeds=int(group["n_seeds"].iloc[0]),
                                      unit=group["unit"].iloc[0])
        for stat in group.itertuples(index=False):
            row[str(stat.statistic)] = fmt_ci(stat.estimate, stat.ci_low, stat.ci_high)
        rows.append(row)
    columns = ["method", "n", "seeds", "unit", *pd.unique(summary["statistic"])]
    rows += [dict(method=m, n=0, seeds=0, unit="missing") for m in missing]
    table = pd.DataFrame(rows, columns=columns)
    order = {m: i for i, m in enumerate(method_order(table["method"]))}
    return table.sort_values("method", key=lambda s: s.map(order)).reset_index(drop=True)


def budget_table(robots: pd.DataFrame) -> pd.DataFrame:
    """Per method: robots, runs and the median, min and max env steps per robot."""
    table = robots.groupby("method")["budget"].agg(["median", "min", "max"])
    table.insert(0, "runs", robots.groupby("method")["run"].nunique())
    table.insert(0, "robots", robots.groupby("method").size())
    return table.loc[method_order(table.index)].reset_index()


# ---------------------------------------------------------------- figures


def select_robots(robots: pd.DataFrame, run: str, n: int = LEARNING_CURVES) -> list[str]:
    """Up to ``n`` robots of a run spread over its fitness ranks, best first.

    Ranks are spaced evenly from the best to the worst robot with a fitness, so the
    figure shows the spread of learning abilities as the paper's Figs. 9 and 11 do.
    """
    rows = robots[(robots["run"] == run) & np.isfinite(robots["fitness"])]
    rows = rows.sort_values("fitness", ascending=False)
    picks = np.unique(np.linspace(0, len(rows) - 1, min(n, len(rows))).round().astype(int))
    return cast(list[str], rows["name"].iloc[picks].tolist())  # pandas is untyped


def ablation_figures(
    robots: pd.DataFrame,
    curves: pd.DataFrame,
    out: str | Path | None = None,
    *,
    population_size: int = 20,
) -> dict[str, Figure]:
    """The paper's figures for these runs, written as ``out/<key>.png`` when ``out`` is given.

    Args:
        robots: Robots table.
        curves: Curves table.
        out: Folder for the PNGs, or None to only build the figures.
        population_size: Initial population size (for the population replay).

    Returns:
        File stem → figure: ``fitness_vs_RR`` (Figs. 13–15, when a method besides R+R
        is present), ``evolution_<run>`` per run (Figs. 10, 12), ``curves_<run>`` per run
        with learning curves (Figs. 9, 11) and ``best_so_far``.
    """
    folder = None if out is None else Path(out)

    def path(stem: str) -> Path | None:
        return None if folder is None else folder / f"{stem}.png"

    figures: dict[str, Figure] = {}
    scored = fully_trained(robots)
    others = [m for m in method_order(scored["method"]) if m != "R+R"]
    if others:
        figures["fitness_vs_RR"] = plots.plot_against_baseline(
            scored, others, path=path("fitness_vs_RR"))
    for run in sorted(scored["run"].unique()):
        stem = f"evolution_{safe_name(run)}"
        figures[stem] = plots.plot_evolution(scored, run, population_size=population_size,
                                             path=path(stem))
        names = [n for n in select_robots(scored, run)
                 if ((curves["run"] == run) & (curves["name"] == n)).any()]
        if names:
            stem = f"curves_{safe_name(run)}"
            fitness = scored[scored["run"] == run].set_index("name")["fitness"]
            labels = [f"{n} ({fitness[n]:+.3f})" for n in names]
            fig = plots.plot_learning_curves(curves, names, run, labels=labels)
            fig.axes[0].set_title(f"{run}: learning curves (fitness in brackets)")
            figures[stem] = plots.finish(fig, path(stem))
    if len(scored):
        figures["best_so_far"] = plots.plot_best_so_far(scored, path=path("best_so_far"))
    return figures


# ---------------------------------------------------------------- Markdown


PAPER_NOTE = (
    "The paper's numbers come from its Unity/ML-Agents task (12 arenas, 30,000 env steps "
    "per robot); ours from the MuJoCo re-implementation with the budgets above. Episode "
    "length, physics, reward shaping and success rate differ, so reward scales differ: "
    "compare the ordering of the methods and the sign of the contrasts, not the values."
)


def ablation_markdown(runs: Runs, tables: AblationTables, figures: dict[str, Path],
                      out: Path) -> str:
    """The report's Markdown text.

    Args:
        runs: What :func:`analysis.load.load_runs` read.
        tables: :func:`ablation_tables` of ``runs.robots``.
        figures: File stem → written PNG path.
        out: Folder of the report (links are relative to it).

    Returns:
        The Markdown text.
    """
    t = tables
    extra = [m for m in t.present if m in EXTRA_METHODS]
    parts = [f"# Ablation: {', '.join(['R+R', 'R+L', 'E+R', 'E+L', *extra])}\n\n",
             f"Methods present: {', '.join(t.present) or 'none'}. "
             f"Missing: {', '.join(t.missing) or 'none'}.\n\n"]
    parts += [f"- {note}\n" for note in [*runs.notes, *t.notes]]
    parts += ["\n## Runs\n\n", markdown_table(runs.runs.drop(columns="path")),
              "\n### Env steps per robot\n\n", markdown_table(t.budgets, digits=0)]
    parts += ["\n## Fitness per method\n\n",
              "Estimates with bootstrap 95 % CIs; `unit` is the resampling unit (the robot, "
              "or the whole GA run for an evolved method with several seeds).\n\n",
              markdown_table(t.main)]
    deployed = deployed_table(runs.robots)
    if not deployed.empty:
        parts += ["\n### The deployed controller\n\n",
                  "Per method, over the robots whose training ran periodic deterministic "
                  "evaluations (`learner.eval_interval`): the fitness (Eq. 8, earned with "
                  "the policy's noise) beside the handed-back policy's deterministic "
                  "success and return (its mean action, as it is deployed and replayed).\n\n",
                  markdown_table(deployed)]
    parts += ["\n## Tests\n", tests_markdown("robots", t.kruskal, t.pairwise)]
    if t.per_run is not None:
        parts.append(tests_markdown("per-run means", *t.per_run))
    if not t.extra_pairwise.empty:
        parts += ["\n### Beyond the paper's methods, on robots\n\n",
                  "Each pair its own question, outside the Holm family above: two-sided "
                  "Mann–Whitney U; A12 = P(a beats b).\n\n", markdown_table(t.extra_pairwise)]
    parts.append("\n## Interaction: does evolution pay off only with learning?\n\n")
    if t.interaction is None:
        parts.append(f"Not computed: needs all four methods (missing: {', '.join(t.missing)}).\n")
    else:
        shown = t.interaction.assign(
            **{"estimate [CI]": [fmt_ci(r.estimate, r.ci_low, r.ci_high)
                                 for r in t.interaction.itertuples()]})
        parts.append(markdown_table(shown[["contrast", "estimate [CI]"]]))
    if t.nested is not None:
        parts.append(nested_markdown(t.nested))
    parts += ["\n## Beside the paper\n\n", PAPER_NOTE + "\n\n",
              _order_markdown(paper_rows(t.summary)),
              "\n", markdown_table(t.paper)]
    parts.append("\n## Figures\n")
    for stem, path in figures.items():
        parts.append(f"\n### {_caption(stem)}\n\n" + figure_link(path, out, stem))
    return "".join(parts)


def deployed_table(robots: pd.DataFrame) -> pd.DataFrame:
    """Per method with deterministic evaluations: robots evaluated, and the mean
    fitness, deterministic success rate and deterministic return over them (empty when
    no robot has one)."""
    rated = robots[np.isfinite(robots["eval_success_rate"].to_numpy(float))]
    if rated.empty:
        return pd.DataFrame()
    grouped = rated.groupby("method", sort=False)
    return pd.DataFrame(dict(
        evaluated=grouped.size(), fitness=grouped["fitness"].mean(),
        eval_success_rate=grouped["eval_success_rate"].mean(),
        eval_mean_return=grouped["eval_mean_return"].mean(),
    )).rename_axis("method").reset_index()


def method_ranking(summary: pd.DataFrame, statistic: str) -> str:
    """Methods by decreasing ``statistic`` estimate, as ``"E+L > R+L > ..."``."""
    rows = summary[summary["statistic"] == statistic].dropna(subset=["estimate"])
    return " > ".join(rows.sort_values("estimate", ascending=False)["method"])


def _order_markdown(summary: pd.DataFrame) -> str:
    lines = []
    for statistic in ("max", "mean"):
        paper = robot_level.PAPER_ABLATION[robot_level.PAPER_ABLATION["statistic"] == statistic]
        paper_order = " > ".join(paper.sort_values("paper", ascending=False)["method"])
        lines.append(f"- Order by {statistic}: paper {paper_order}; "
                     f"ours {method_ranking(summary, statistic) or '–'}.\n")
    return "".join(lines)


def tests_markdown(unit: str, kruskal: robot_level.GroupTest | None, pairwise: pd.DataFrame) -> str:
    """The Kruskal–Wallis result and the pairwise table as Markdown (``unit``: what was
    compared, e.g. ``"robots"``)."""
    text = f"\n### On {unit}\n\n"
    if kruskal is not None:
        text += (f"Kruskal–Wallis over {', '.join(kruskal.methods)}: "
                 f"H = {kruskal.statistic:.3f}, p = {kruskal.pvalue:.3g}.\n\n")
    if not pairwise.empty:
        text += ("Pairwise two-sided Mann–Whitney U, Holm-adjusted; A12 = P(a beats b).\n\n"
                 + markdown_table(pairwise))
    return text


def _caption(stem: str) -> str:
    if stem == "fitness_vs_RR":
        return "Fitness per robot in birth order, each method against R+R (Figs. 13–15)"
    if stem == "best_so_far":
        return "Best fitness so far against cumulative env steps"
    kind, _, run = stem.partition("_")
    if kind == "evolution":
        return f"Fitness over the evolution, run {run} (Figs. 10, 12)"
    return f"Learning curves of selected robots, run {run} (Figs. 9, 11)"


# ---------------------------------------------------------------- CLI


def write_report(runs: Runs, out: str | Path, *, resampling: Resampling | None = None
                 ) -> Path:
    """Compute the tables, draw the figures and write ``out/report.md``.

    Args:
        runs: The runs, as :func:`analysis.load.load_runs` read them.
        out: Report folder (created).
        resampling: How the intervals are drawn; None for seed 0 and 2000 resamples.

    Returns:
        The path of the Markdown report.

    Raises:
        RunDirectoryError: If no robot of the runs has a fitness.
    """
    if not np.isfinite(runs.robots["fitness"].to_numpy(dtype=float)).any():
        raise RunDirectoryError(f"{runs.where}: no robot with a fitness (no evaluation finished)")
    out = report_folder(out)
    tables = ablation_tables(runs.robots, resampling or Resampling.seeded(0),
                             population_size=runs.population_size)
    figures = ablation_figures(runs.robots, runs.curves, out,
                               population_size=runs.population_size)
    written = {stem: out / f"{stem}.png" for stem in figures}
    report = out / REPORT
    report.write_text(ablation_markdown(runs, tables, written, out), encoding="utf-8")
    tables.summary.to_csv(out / "summary.csv", index=False)
    tables.pairwise.to_csv(out / "pairwise.csv", index=False)
    if tables.nested is not None:
        write_nested_tables(tables.nested, out)
    return report


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m analysis.report RUN... --out DIR``; exit 0, or 2 on a bad input."""
    cli = parser("Ablation report (paper section 8) of evo runs.",
                 prog="python -m analysis.report")
    cli.add_argument("--history-only", action="store_true",
                     help="read only each run's history.csv and summary.json (committed "
                          "copies; seed from a <method>_seed<S> name): no learning curves")
    args = cli.parse_args(argv)
    load = load_histories if args.history_only else load_runs
    return run_report(lambda: write_report(load(args.runs, args.first), args.out,
                                           resampling=resampling_of(args)))


if __name__ == "__main__":
    sys.exit(main())
