"""Early rejection replayed on fully trained offspring: what a stopping rule would have
stopped, what it would have saved, and whether it would stop new bodies more often.

For every offspring of runs trained with the rule off, the rule (``evo.early_rejection``,
as the GA applies it) is replayed on its recorded learning curve against the population
minimum it actually had to beat (:func:`replay`); :func:`score` gives the false
rejections (accepted offspring the rule stops, with a Wilson interval) and the env steps
saved. :func:`bias` asks whether the offspring the rule stops differ in body from the
others beyond what their final fitness explains: a logistic model of ``stopped`` on how
far the final fitness lies above the minimum it faced and on each body measure (module
count, motors, pivots, and the modules changed from the nearer parent), each measure's
coefficient tested with the fitness held fixed (Holm-adjusted).

    python -m analysis.rejection RUN... --checkpoints 0.4 --predictor rate --margin 0.5 \\
        [--first 60] --out DIR       # bias.md, offspring.csv, bias.png
"""

from __future__ import annotations

import argparse
import sys
import warnings
from collections.abc import Sequence
from pathlib import Path
from typing import NotRequired, TypedDict

import numpy as np
import pandas as pd
import scipy.stats
import statsmodels.api as sm

from analysis.load import Runs, load_runs, read_config
from analysis.markdown import markdown_table
from analysis.population import population_trace
from analysis.stats import holm, wilson
from evo.early_rejection import Curve, EarlyRejection, replay_rule
from evo.robot import load_robot
from evo.robot.tree import Robot

BODY = ("modules", "motors", "pivots", "changed")
"""The body measures :func:`bias` tests: module count (wheels included), motors, pivots,
and modules changed from the nearer parent (:func:`modules_changed`)."""


# ---------------------------------------------------------------- the replay


def replay(robots: pd.DataFrame, curves: pd.DataFrame, population_sizes: dict[str, int],
           rule: EarlyRejection, t_max: dict[str, int] | None = None) -> pd.DataFrame:
    """Per offspring: the minimum it faced, whether it was accepted, whether (and at
    which fraction of its budget) the rule stops it (``t_max``: each run's episode
    length, for the ``rate`` predictor; 1,000 control steps where not given)."""
    rows = []
    for run, run_robots in robots.groupby("run"):
        trace = population_trace(run_robots, population_sizes.get(str(run), 20))
        merged = run_robots.merge(trace[["name", "threshold"]], on="name")
        by_name = {name: Curve.from_rows(c) for name, c in
                   curves[curves["run"] == run].groupby("name")}
        for robot in merged.itertuples(index=False):
            if not np.isfinite(robot.threshold) or robot.name not in by_name:
                continue
            budget = float(robot.scheduled_budget or robot.budget)  # as the GA gave it
            verdict = replay_rule(rule, by_name[robot.name], budget, float(robot.threshold),
                                  (t_max or {}).get(str(run), 1000))
            rows.append(dict(run=run, name=robot.name, budget=budget,
                             accepted=bool(robot.accepted), threshold=robot.threshold,
                             fitness=float(robot.fitness), stopped=verdict is not None,
                             fraction=verdict.fraction if verdict else 1.0))
    return pd.DataFrame(rows)


def replay_runs(runs: Runs, rule: EarlyRejection) -> tuple[pd.DataFrame, float]:
    """:func:`replay` on the robots of ``runs`` (those trained over their whole budget),
    with every run's own ``t_max``; and the env steps those robots took in all."""
    robots = runs.robots[runs.robots["status"] != "stopped-early"]
    t_max = {str(r.run): read_config(Path(r.path)).t_max for r in runs.runs.itertuples()}
    offspring = replay(robots, runs.curves, runs.population_sizes, rule, t_max)
    return offspring, float(robots["budget"].sum())


class Score(TypedDict):
    """A rule's replay (:func:`score`); with no offspring, only their count."""

    offspring: int
    accepted: NotRequired[int]
    stopped: NotRequired[int]
    false_rejections: NotRequired[float]  # share of the accepted offspring the rule stops
    ci_low: NotRequired[float]  # Wilson CI of false_rejections
    ci_high: NotRequired[float]
    saved: NotRequired[float]  # share of the rejected offspring's env steps saved
    schedule: NotRequired[float]  # all env steps over those left to train


def score(offspring: pd.DataFrame, all_steps: float) -> Score:
    """False rejections (with a Wilson CI), env steps saved, schedule ratio."""
    if offspring.empty:
        return Score(offspring=0)
    accepted = offspring[offspring["accepted"]]
    rate, low, high = wilson(int(accepted["stopped"].sum()), len(accepted))
    rejected = offspring[~offspring["accepted"]]
    saved = float(((1 - rejected["fraction"]) * rejected["budget"]).sum())
    lost = float(((1 - accepted["fraction"]) * accepted["budget"]).sum())
    return Score(
        offspring=len(offspring), accepted=len(accepted), stopped=int(offspring["stopped"].sum()),
        false_rejections=rate, ci_low=low, ci_high=high,
        saved=saved / max(float(rejected["budget"].sum()), 1.0),
        schedule=all_steps / max(all_steps - saved - lost, 1.0),
    )


# ---------------------------------------------------------------- the bodies


def modules_changed(child: Robot, parent: Robot) -> int:
    """Modules (wheels included) of either body without a module of the same type in
    the same lattice cell in the other: how much of the body crossover changed."""
    def cells(robot: Robot) -> set[tuple[tuple[int, int, int], str]]:
        return {(p.cell, p.node.type.value) for p in robot.modules()}
    return len(cells(child) ^ cells(parent))


def body_measures(run_dir: Path, names: Sequence[str], parents: Sequence[Sequence[str]]
                  ) -> pd.DataFrame:
    """:data:`BODY` of each robot ``names[i]`` of a run (``robots/<name>.json``), its
    ``changed`` counted from the nearer of ``parents[i]`` (NaN when none is on file)."""
    folder = run_dir / "robots"
    cache: dict[str, Robot | None] = {}

    def robot(name: str) -> Robot | None:
        if name not in cache:
            path = folder / f"{name}.json"
            cache[name] = load_robot(path) if path.is_file() else None
        return cache[name]

    rows = []
    for name, mine in zip(names, parents, strict=True):
        child = robot(name)
        if child is None:
            raise ValueError(f"{folder / (name + '.json')}: missing; the bias study reads "
                             "every offspring's body from its run's robots/")
        known = [p for p in (robot(q) for q in mine) if p is not None]
        rows.append(dict(name=name, modules=len(child), motors=child.n_motors,
                         pivots=child.n_pivots,
                         changed=min((modules_changed(child, p) for p in known),
                                     default=np.nan)))
    return pd.DataFrame(rows)


def with_bodies(offspring: pd.DataFrame, robots: pd.DataFrame,
                paths: dict[str, Path]) -> pd.DataFrame:
    """``offspring`` (a :func:`replay` table) with every offspring's :data:`BODY`."""
    parts = []
    for run, rows in offspring.groupby("run"):
        mine = robots[robots["run"] == run].set_index("name")
        parents = [[p for p in str(mine.loc[n, "parents"]).split(";") if p]  # "a;b"
                   for n in rows["name"]]
        parts.append(rows.merge(body_measures(paths[str(run)], list(rows["name"]), parents),
                                on="name"))
    return pd.concat(parts, ignore_index=True)


# ---------------------------------------------------------------- the bias test


def bias(offspring: pd.DataFrame, measures: Sequence[str] = BODY) -> pd.DataFrame:
    """Whether the stopped offspring differ in body beyond what their fitness explains.

    For each measure, a logistic model ``stopped ~ excess + measure`` (``excess``: final
    fitness minus the minimum faced; a pivot-free sample's pivots are left out) and the
    measure's coefficient with its Wald p-value, Holm-adjusted over the measures; beside
    it, the measure's medians among stopped and kept offspring and a Mann–Whitney p
    that does not hold the fitness fixed (descriptive).

    Returns:
        One row per measure: ``measure``, ``stopped_median``, ``kept_median``,
        ``p_unadjusted_mw``, ``coef`` (log-odds per unit, fitness held), ``ci_low``,
        ``ci_high``, ``p``, ``p_holm``, ``n``.
    """
    data = offspring.assign(excess=offspring["fitness"] - offspring["threshold"])
    rows = []
    for measure in measures:
        part = data[["stopped", "excess", measure]].dropna()
        stopped, kept = part[part["stopped"]], part[~part["stopped"]]
        row: dict[str, object] = dict(
            measure=measure, n=len(part), stopped=len(stopped),
            stopped_median=float(stopped[measure].median()) if len(stopped) else np.nan,
            kept_median=float(kept[measure].median()) if len(kept) else np.nan,
            p_unadjusted_mw=(float(scipy.stats.mannwhitneyu(stopped[measure],
                                                            kept[measure]).pvalue)
                             if len(stopped) and len(kept) else np.nan))
        if len(stopped) >= 2 and part[measure].nunique() > 1:
            design = sm.add_constant(part[["excess", measure]].astype(float))
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")  # near-separation: reported by the CI's width
                fit = sm.Logit(part["stopped"].astype(float), design).fit(disp=0,
                                                                          maxiter=200)
            low, high = fit.conf_int().loc[measure]
            row.update(coef=float(fit.params[measure]), ci_low=float(low),
                       ci_high=float(high), p=float(fit.pvalues[measure]))
        rows.append(row)
    table = pd.DataFrame(rows)
    table["p_holm"] = holm(table["p"].to_numpy(dtype=float)) if "p" in table else np.nan
    return table


def plot_bias(offspring: pd.DataFrame, out: Path, measures: Sequence[str] = BODY) -> Path:
    """Each body measure against the fitness excess, stopped offspring marked."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    excess = offspring["fitness"] - offspring["threshold"]
    fig, axes = plt.subplots(1, len(measures), figsize=(3.2 * len(measures), 3.2),
                             sharey=True)
    rng = np.random.default_rng(0)  # jitter only, so integer measures do not overlap
    for ax, measure in zip(np.atleast_1d(axes), measures, strict=True):
        for stopped, colour, label in ((False, "tab:blue", "trained on"),
                                       (True, "tab:red", "stopped")):
            rows = offspring["stopped"] == stopped
            x = offspring.loc[rows, measure] + rng.uniform(-0.2, 0.2, int(rows.sum()))
            ax.scatter(x, excess[rows], s=10, alpha=0.6, color=colour, label=label)
        ax.axhline(0, color="grey", lw=0.8)
        ax.set_xlabel({"changed": "modules changed from parent"}.get(measure, measure))
    np.atleast_1d(axes)[0].set_ylabel("final fitness − minimum faced")
    np.atleast_1d(axes)[0].legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(out, dpi=120)
    plt.close(fig)
    return out


# ---------------------------------------------------------------- the command


def main(argv: Sequence[str] | None = None) -> int:
    cli = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    cli.add_argument("runs", nargs="+", type=Path)
    cli.add_argument("--checkpoints", nargs="+", type=float, default=[0.4])
    cli.add_argument("--predictor", default="rate")
    cli.add_argument("--margin", type=float, default=0.5)
    cli.add_argument("--first", type=int, default=None,
                     help="replay each run's first N robots only (default: all)")
    cli.add_argument("--out", type=Path, required=True)
    args = cli.parse_args(argv)
    try:
        rule = EarlyRejection(enabled=True, checkpoints=tuple(args.checkpoints),
                              predictor=args.predictor, margin=args.margin)
    except ValueError as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    runs = load_runs(args.runs, first=args.first)
    offspring, all_steps = replay_runs(runs, rule)
    if offspring.empty:
        print(f"error: no offspring to replay in {runs.where}", file=sys.stderr)
        return 2
    paths = {str(r.run): Path(r.path) for r in runs.runs.itertuples()}
    offspring = with_bodies(offspring, runs.robots, paths)
    table = bias(offspring)
    args.out.mkdir(parents=True, exist_ok=True)
    offspring.to_csv(args.out / "offspring.csv", index=False)
    plot_bias(offspring, args.out / "bias.png")
    scored = pd.DataFrame([score(offspring, all_steps)])
    text = (f"# Early rejection's bias against new bodies\n\nRule: {args.predictor} at "
            f"{list(args.checkpoints)} of the budget, margin {args.margin}; runs: "
            f"{', '.join(runs.runs['run'])}.\n\n{markdown_table(scored)}\n\n"
            f"{markdown_table(table)}\n")
    (args.out / "bias.md").write_text(text)
    print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
