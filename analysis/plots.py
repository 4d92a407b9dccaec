"""The figures of every study: the paper's, redrawn from a robots table and a curves table,
and those of the studies beyond it.

Every function builds a :class:`matplotlib.figure.Figure` on the Agg canvas (no pyplot,
no global state, no display needed), returns it, and writes a PNG when given ``path``.

* :func:`plot_against_baseline`: fitness per robot in birth order, each method against
  ``R+R`` (paper Figs. 13–15).
* :func:`plot_evolution`: fitness of every robot over the evolution with the
  population's best and mean (Figs. 10, 12).
* :func:`plot_learning_curves`: mean return during training of selected robots
  (Figs. 9, 11).
* :func:`plot_cost_traces`: best fitness so far against env steps spent, one line per
  run, the figure of every study that compares at equal cost; :func:`plot_best_so_far`,
  the ablation's.
* :func:`plot_rank_metrics`, :func:`plot_rejection_tradeoff`, :func:`plot_early_scatter`:
  the early-slope study (:mod:`analysis.early_slope`).
* :func:`plot_seed_scatter`: fitness under one training seed against another, one point
  per structure (the noise ceiling, :mod:`analysis.noise_ceiling`).
* :func:`plot_designer`: every retrained robot's metrics with their intervals, evolved
  against hand-made (:mod:`analysis.designer`).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np
import pandas as pd
from matplotlib.axes import Axes
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.transforms import blended_transform_factory

from analysis.population import best_so_far, population_trace
from analysis.tables import CURVE_COLUMNS, method_order, require_columns

METHOD_COLORS: dict[str, str] = {
    "R+R": "tab:blue",  # the paper's colours: blue, yellow, green; E+L ours in red
    "R+L": "goldenrod",
    "E+R": "tab:green",
    "E+L": "tab:red",
    "E+L+I": "tab:purple",  # E+L with policy inheritance, the fifth arm
}
ORIGIN_COLORS: dict[str, str] = {"evolved": "tab:red", "designed": "tab:blue"}
"""A robot's origin in :mod:`analysis.designer`: evolved in red as E+L, hand-made in blue."""
ORIGIN_LABELS: dict[str, str] = {"evolved": "evolved", "designed": "hand-made"}


def new_figure(n_axes: int = 1, *, width: float = 6.4, height: float = 4.0,
               sharey: bool = False) -> tuple[Figure, list[Axes]]:
    """A figure with ``n_axes`` side-by-side axes on an Agg canvas."""
    fig = Figure(figsize=(width * n_axes, height), layout="constrained")
    FigureCanvasAgg(fig)
    axes = fig.subplots(1, n_axes, sharey=sharey, squeeze=False)[0]
    return fig, list(axes)


def finish(fig: Figure, path: str | Path | None, dpi: int = 150) -> Figure:
    """Save ``fig`` as PNG at ``path`` (parents created) when given; return it."""
    if path is not None:
        Path(path).parent.mkdir(parents=True, exist_ok=True)
        fig.savefig(path, dpi=dpi, format="png")
    return fig


def plot_against_baseline(
    robots: pd.DataFrame,
    methods: Sequence[str] = ("E+R", "R+L", "E+L"),
    *,
    baseline: str = "R+R",
    value: str = "fitness",
    path: str | Path | None = None,
) -> Figure:
    """Fitness per robot in birth order, one panel per method, each against the baseline.

    Args:
        robots: Robots table; all seeds of a method are drawn in one colour.
        methods: Methods to compare, one panel each (paper: Fig. 13 E+R, 14 R+L, 15 E+L).
        baseline: Method drawn in every panel.
        value: Column on the y axis.
        path: PNG to write, or None.

    Returns:
        The figure, one axes per method, each with two point collections.
    """
    require_columns(robots, ("method", "birth", value), "robots table")
    fig, axes = new_figure(len(methods), width=4.8, sharey=True)
    for ax, method in zip(axes, methods, strict=True):
        for m in (baseline, method):
            rows = robots[robots["method"] == m]
            ax.scatter(rows["birth"], rows[value], s=12, alpha=0.8, label=m,
                       color=METHOD_COLORS.get(m))
        ax.set(title=f"{method} vs {baseline}", xlabel="robot (birth order)")
        ax.legend(loc="lower right")
    axes[0].set_ylabel(value)
    return finish(fig, path)


def plot_evolution(
    robots: pd.DataFrame,
    run: str | None = None,
    *,
    population_size: int = 20,
    path: str | Path | None = None,
) -> Figure:
    """Every robot's fitness over one run, with the population's best and mean after it.

    Args:
        robots: Robots table.
        run: Run to draw; None when the table holds a single run.
        population_size: Initial population size (for the replay).
        path: PNG to write, or None.

    Returns:
        The figure: one axes, robots as points (accepted filled, rejected hollow) and
        two lines, population best and mean.

    Raises:
        ValueError: If ``run`` is None and the table holds several runs.
    """
    require_columns(robots, ("run", "birth", "fitness", "accepted"), "robots table")
    if run is None:
        runs = robots["run"].unique()
        if len(runs) != 1:
            raise ValueError(f"robots table holds runs {list(runs)}; pass run=")
        run = str(runs[0])
    rows = robots[robots["run"] == run].sort_values("birth")
    trace = population_trace(rows, population_size)
    fig, (ax,) = new_figure()
    accepted = rows["accepted"].astype(bool)
    ax.scatter(rows.loc[accepted, "birth"], rows.loc[accepted, "fitness"], s=14,
               color="tab:blue", label="accepted")
    ax.scatter(rows.loc[~accepted, "birth"], rows.loc[~accepted, "fitness"], s=14,
               facecolors="none", edgecolors="tab:gray", label="rejected")
    ax.plot(trace["birth"], trace["pop_max"], color="tab:red", label="population best")
    ax.plot(trace["birth"], trace["pop_mean"], color="tab:orange", label="population mean")
    ax.set(title=run, xlabel="robot (birth order)", ylabel="fitness")
    ax.legend(loc="lower right")
    return finish(fig, path)


def plot_learning_curves(
    curves: pd.DataFrame,
    names: Sequence[str],
    run: str | None = None,
    *,
    labels: Sequence[str] | None = None,
    window: int = 1,
    path: str | Path | None = None,
) -> Figure:
    """Mean return during training of selected robots, one line each (Figs. 9, 11).

    Args:
        curves: Curves table.
        names: Robots to draw.
        run: Their run; None to match names in any run.
        labels: Legend labels, one per name (default: the names).
        window: Rolling mean over this many informative batches (1: raw).
        path: PNG to write, or None.

    Returns:
        The figure: one axes with one line per robot.
    """
    require_columns(curves, CURVE_COLUMNS, "curves table")
    rows = curves if run is None else curves[curves["run"] == run]
    fig, (ax,) = new_figure()
    for name, label in zip(names, labels or names, strict=True):
        curve = rows[rows["name"] == name].dropna(subset=["train/mean_return"])
        curve = curve.sort_values("env_steps")
        smooth = curve["train/mean_return"].rolling(window, min_periods=1).mean()
        ax.plot(curve["env_steps"], smooth, label=label)
    ax.set(xlabel="env steps", ylabel="mean return")
    ax.legend(fontsize="small")
    return finish(fig, path)


def plot_cost_traces(
    trace: pd.DataFrame,
    *,
    by: str,
    colors: Mapping[str, str],
    legend: str = "{}",
    panels: Sequence[tuple[str, str]] = (("best", "best fitness so far"),),
    xlabel: str = "env steps (cumulative)",
    mark: float | None = None,
    path: str | Path | None = None,
) -> Figure:
    """Best fitness so far (and other figures of a run) against cumulative env steps, one
    step line per run, coloured by its group: every best-so-far figure of the studies.

    Args:
        trace: :func:`analysis.population.cost_trace` of the runs (``run``, ``by``,
            ``env_steps`` and the panels' columns); runs are drawn in the order they
            first appear, so the last drawn lies on top.
        by: The column that groups the runs (a method, an arm of a comparison).
        colors: Group → colour (matplotlib's next colour for a group without one).
        legend: The legend label of a group, ``legend.format(group)``, on the first run
            of each group.
        panels: Per axes, the column drawn and its y label.
        xlabel: The x label of every axes.
        mark: Env steps to mark with a dashed vertical line (labelled ``E``), or None.
        path: PNG to write, or None.

    Returns:
        The figure: one axes per panel, one step line per run in each.
    """
    fig, axes = new_figure(len(panels))
    labelled: set[str] = set()
    for _, rows in trace.groupby("run", sort=False):
        group = str(rows[by].iloc[0])
        label = None if group in labelled else legend.format(group)
        labelled.add(group)
        for ax, (column, _) in zip(axes, panels, strict=True):
            ax.step(rows["env_steps"], rows[column], where="post", color=colors.get(group),
                    label=label)
    for ax, (_, ylabel) in zip(axes, panels, strict=True):
        if mark is not None:
            ax.axvline(mark, color="grey", linestyle="--", label="E")
        ax.set(xlabel=xlabel, ylabel=ylabel)
    axes[0].legend(loc="lower right")
    return finish(fig, path)


def plot_best_so_far(robots: pd.DataFrame, *, path: str | Path | None = None) -> Figure:
    """Best fitness so far against env steps spent so far, one line per run
    (:func:`plot_cost_traces` of :func:`analysis.population.best_so_far`).

    Args:
        robots: Robots table.
        path: PNG to write, or None.

    Returns:
        The figure: one axes, one step line per run, coloured by method, the methods in
        :data:`analysis.tables.METHODS` order.
    """
    trace = best_so_far(robots)
    order = {m: i for i, m in enumerate(method_order(trace["method"]))}
    trace = trace.sort_values("method", key=lambda m: m.map(order), kind="stable")
    return plot_cost_traces(trace, by="method", colors=METHOD_COLORS, path=path)


# ---------------------------------------------------------------- early-slope study


def plot_rank_metrics(
    metrics: pd.DataFrame,
    target: str = "fitness",
    *,
    ceiling: float | None = None,
    path: str | Path | None = None,
) -> Figure:
    """Spearman ρ, Kendall τ and top recall of every predictor against the cut.

    Args:
        metrics: :func:`analysis.early_slope.rank_metrics`.
        target: Which target's rows to draw.
        ceiling: The noise ceiling ρ, drawn as a dashed line on the Spearman panel.
        path: PNG to write, or None.

    Returns:
        The figure: one axes per metric, one line with CI error bars per predictor.
    """
    require_columns(metrics, ("target", "fraction", "predictor", "metric", "estimate",
                              "ci_low", "ci_high"), "rank metrics table")
    rows = metrics[metrics["target"] == target]
    names = list(pd.unique(rows["metric"]))
    fig, axes = new_figure(max(len(names), 1), width=4.4)
    for ax, metric in zip(axes, names, strict=False):
        for predictor, line in rows[rows["metric"] == metric].groupby("predictor", sort=False):
            line = line.sort_values("fraction")
            error = [line["estimate"] - line["ci_low"], line["ci_high"] - line["estimate"]]
            ax.errorbar(line["fraction"], line["estimate"], yerr=error, marker="o",
                        capsize=2, label=str(predictor))
        if metric == "spearman" and ceiling is not None and np.isfinite(ceiling):
            ax.axhline(ceiling, color="black", linestyle="--", label="noise ceiling")
        ax.set(title=f"{metric} vs {target}", xlabel="cut (fraction of budget)")
    axes[0].legend(fontsize="small")
    return finish(fig, path)


def plot_rejection_tradeoff(tradeoff: pd.DataFrame, *, title: str = "",
                            path: str | Path | None = None) -> Figure:
    """Compute saved against good robots lost by early rejection, per predictor.

    Args:
        tradeoff: :func:`analysis.early_slope.rejection_tradeoff` (one target).
        title: Axes title (which rejection rule).
        path: PNG to write, or None.

    Returns:
        The figure: one axes, one line per predictor through its cuts, each point
        labelled with its cut.
    """
    require_columns(tradeoff, ("fraction", "predictor", "saved_share", "top_k_lost"),
                    "rejection trade-off table")
    fig, (ax,) = new_figure()
    for predictor, line in tradeoff.groupby("predictor", sort=False):
        line = line.sort_values("fraction")
        ax.plot(line["saved_share"], line["top_k_lost"], marker="o", label=str(predictor))
        for row in line.itertuples(index=False):
            ax.annotate(f"{row.fraction:g}", (row.saved_share, row.top_k_lost), fontsize=7,
                        textcoords="offset points", xytext=(3, 3))
    ax.set(title=title, xlabel="share of env steps saved", ylabel="top-k robots rejected")
    ax.legend(fontsize="small")
    return finish(fig, path)


def plot_early_scatter(preds: pd.DataFrame, fraction: float, *,
                       path: str | Path | None = None) -> Figure:
    """Each predictor's prediction against the actual target at one cut.

    Args:
        preds: :func:`analysis.early_slope.predictions` (one target).
        fraction: The cut to draw.
        path: PNG to write, or None.

    Returns:
        The figure: one axes per predictor, one point per robot, coloured by method.
    """
    require_columns(preds, ("fraction", "predictor", "prediction", "actual", "method"),
                    "predictions table")
    rows = preds[np.isclose(preds["fraction"], fraction)]
    names = list(pd.unique(rows["predictor"]))
    fig, axes = new_figure(max(len(names), 1), width=3.6)
    for ax, predictor in zip(axes, names, strict=False):
        for method in method_order(rows["method"]):
            points = rows[(rows["predictor"] == predictor) & (rows["method"] == method)]
            ax.scatter(points["prediction"], points["actual"], s=12, label=method,
                       color=METHOD_COLORS.get(method))
        ax.set(title=f"{predictor} at {fraction:g}", xlabel="prediction")
    if len(rows):
        axes[0].set_ylabel(str(rows["target"].iloc[0]) if "target" in rows else "actual")
        axes[0].legend(fontsize="small")
    return finish(fig, path)


def plot_seed_scatter(seeds: pd.DataFrame, baseline: pd.DataFrame, *,
                      estimators: Sequence[str] = ("fitness",),
                      ceiling: pd.DataFrame | None = None, margin: float = 0.0,
                      path: str | Path | None = None) -> Figure:
    """Fitness under the first training seed against the second, per estimator.

    Args:
        seeds: Trainings with ``structure``, ``replicate`` and the estimator columns.
        baseline: The random learner's trainings (same columns), possibly empty: the
            structures whose mean fitness does not beat it by more than ``margin`` are
            drawn hollow.
        estimators: Fitness columns, one axes each.
        ceiling: :func:`analysis.noise_ceiling.ceiling_table`, for the titles.
        path: PNG to write, or None.

    Returns:
        The figure, with the diagonal drawn in each axes.
    """
    require_columns(seeds, ("structure", "replicate", *estimators), "trainings table")
    fig, axes = new_figure(len(estimators), width=4.4, height=4.2)
    first, second = sorted(seeds["replicate"].unique())[:2]
    for ax, estimator in zip(axes, estimators, strict=True):
        wide = seeds.pivot_table(index="structure", columns="replicate", values=estimator)
        wide = wide.dropna(subset=[first, second])
        base = (baseline.groupby("structure")[estimator].mean().reindex(wide.index)
                if len(baseline) else pd.Series(np.nan, index=wide.index))
        clears = ~(wide.mean(axis=1) <= base + margin)  # NaN baseline: drawn filled
        ax.scatter(wide.loc[clears, first], wide.loc[clears, second], s=22,
                   color="tab:red", label="beats the random learner")
        ax.scatter(wide.loc[~clears, first], wide.loc[~clears, second], s=22,
                   facecolors="none", edgecolors="tab:gray", label="does not")
        values = wide[[first, second]].to_numpy(dtype=float)
        if values.size:
            low, high = float(np.nanmin(values)), float(np.nanmax(values))
            pad = 0.05 * max(high - low, 1e-6)
            ax.plot([low - pad, high + pad], [low - pad, high + pad], color="0.7", lw=1, zorder=0)
        title = estimator
        if ceiling is not None:
            row = ceiling[ceiling["estimator"] == estimator]
            if len(row):
                r = row.iloc[0]
                title += f": ρ {r['spearman']:.2f}, ICC {r['icc']:.2f}"
        ax.set(title=title, xlabel=f"seed {first}", ylabel=f"seed {second}")
    if len(baseline):
        axes[0].legend(fontsize="small", loc="upper left")
    return finish(fig, path)


def plot_noise_study(table: pd.DataFrame, *, path: str | Path | None = None) -> Figure:
    """Spearman rho and ICC (with 95 % CIs) against budget, one line per setting with
    at least two budgets (:func:`analysis.noise_study.study_table`'s numeric columns).

    Args:
        table: Rows of one estimator with ``settings``, ``budget`` and, for ``spearman``
            and ``icc``, ``<metric>_value``, ``<metric>_low`` and ``<metric>_high``.
        path: PNG to write, or None.
    """
    require_columns(table, ("settings", "budget", *(f"{m}_{part}" for m in ("spearman", "icc")
                                                   for part in ("value", "low", "high"))),
                    "noise study table")
    fig, axes = new_figure(2, width=4.8, height=3.6)
    for ax, metric, label in zip(axes, ("spearman", "icc"), ("Spearman ρ across seeds",
                                                            "ICC (share due to structure)"),
                                 strict=True):
        for name, rows in table.groupby("settings", sort=True):
            rows = rows.sort_values("budget")
            if len(rows) < 2:
                continue
            x = rows["budget"].to_numpy(dtype=float) / 1000
            y = rows[f"{metric}_value"].to_numpy(dtype=float)
            err = np.vstack([y - rows[f"{metric}_low"].to_numpy(dtype=float),
                             rows[f"{metric}_high"].to_numpy(dtype=float) - y])
            ax.errorbar(x, y, yerr=err, marker="o", capsize=3, label=str(name))
        ax.axhline(0.8 if metric == "spearman" else 0.0, color="0.7", lw=1, ls="--")
        ax.set_xlabel("budget per robot, thousand env steps")
        ax.set_ylabel(label)
        if ax.get_legend_handles_labels()[0]:  # a setting with two or more budgets
            ax.legend(fontsize=8)
    return finish(fig, path)


# ---------------------------------------------------------------- evolution against the designer

DESIGNER_PANELS = (("success_rate", "success rate", "higher is better"),
                   ("eval_mean_return", "evaluation return", "higher is better"),
                   ("eval_time_to_target", "time to target (s)", "lower is better"))
"""The panels of :func:`plot_designer`: the metric's column prefix, its title, which way."""


def plot_designer(comparison: pd.DataFrame, *, chosen: Sequence[str] = (), title: str = "",
                  path: str | Path | None = None) -> Figure:
    """Every robot's mean over seeds with its 95 % interval, one panel per metric.

    Args:
        comparison: :func:`analysis.designer.comparison_table` (or its ``comparison.csv``):
            ``robot``, ``origin`` and ``<metric>_mean``, ``_low``, ``_high`` per metric;
            robots drawn top to bottom in its order. A missing interval (one seed) draws
            the point alone; a missing mean (no seed reached the target) a dash.
        chosen: The robots to mark (ringed, bold label): the best of each origin.
        title: The figure's title.
        path: PNG to write, or None.

    Returns:
        The figure: one axes per metric (:data:`DESIGNER_PANELS`), robots on the y axis,
        coloured by origin (:data:`ORIGIN_COLORS`).
    """
    require_columns(comparison, ("robot", "origin", *(f"{m}_{k}" for m, _, _ in DESIGNER_PANELS
                                                      for k in ("mean", "low", "high"))),
                    "comparison table")
    n = len(comparison)
    fig, axes = new_figure(len(DESIGNER_PANELS), width=3.4, height=1.9 + 0.28 * max(n, 1),
                           sharey=True)
    y = np.arange(n)
    marked = comparison["robot"].isin(list(chosen)).to_numpy()
    for ax, (metric, name, better) in zip(axes, DESIGNER_PANELS, strict=True):
        mean, low, high = (comparison[f"{metric}_{k}"].to_numpy(dtype=float)
                           for k in ("mean", "low", "high"))
        for origin, color in ORIGIN_COLORS.items():
            rows = (comparison["origin"] == origin).to_numpy() & np.isfinite(mean)
            spans = rows & np.isfinite(low) & np.isfinite(high)
            ax.errorbar(mean[spans], y[spans], xerr=np.clip([mean[spans] - low[spans],
                                                             high[spans] - mean[spans]], 0, None),
                        fmt="none", ecolor=color, capsize=3)
            ax.scatter(mean[rows], y[rows], s=28, color=color, zorder=3)
        ring = marked & np.isfinite(mean)
        ax.scatter(mean[ring], y[ring], s=130, facecolors="none", edgecolors="black",
                   linewidths=1.4, zorder=4)
        at_left = blended_transform_factory(ax.transAxes, ax.transData)
        for i in np.flatnonzero(~np.isfinite(mean)):
            ax.text(0.03, y[i], "not reached" if metric == "eval_time_to_target" else "–",
                    transform=at_left, va="center", fontsize=8, color="0.4")
        ax.set(title=name, xlabel=better)
        ax.grid(axis="x", color="0.9")
        if not np.isfinite(mean).any():
            ax.set_xticks([])  # no values: no scale
    axes[0].set_yticks(y, [str(r) for r in comparison["robot"]])
    axes[0].set_ylim(n - 0.5, -0.5)  # the table's first row on top
    for label, bold in zip(axes[0].get_yticklabels(), marked, strict=True):
        label.set_fontweight("bold" if bold else "normal")
    handles = [Line2D([], [], ls="", marker="o", color=color, label=ORIGIN_LABELS[origin])
               for origin, color in ORIGIN_COLORS.items()]
    handles.append(Line2D([], [], ls="", marker="o", markersize=11, markerfacecolor="none",
                          markeredgecolor="black", label="chosen: best of its origin"))
    fig.legend(handles=handles, loc="outside lower center", ncols=3, fontsize="small")
    if title:
        fig.suptitle(title)
    return finish(fig, path)
