"""Evolution against the designer: the best evolved robots and the hand-made ones, each
retrained from scratch under the same protocol, compared head to head.

The trainings are evo's (``evo.retrain``, ``+exp=designer``): each GA run's best robot
and every hand-made robot trained as ``python evo/main.py +exp=train robot=FILE seed=S``
trains it, with seeds ``0 .. seeds-1``, each training then evaluated deterministically
(``learner.eval_episodes`` episodes of the policy's mean action): its success rate,
mean return and mean time to target (simulated seconds, over the episodes that reached
it). This module reads the folder and compares:

    python evo/main.py +exp=designer 'retrain.runs=[runs/ablation]' env=clean \
        hydra.run.dir=runs/designer                 # the trainings (evo)
    python -m analysis.designer runs/designer       # the comparison

``python -m analysis.designer --runs RUN [RUN ...] --out DIR [--robots robots/]
[--seeds 3] [--confirm 3] [--budget 150000] [--arena clean|cluttered] [--jobs 1]
[overrides...]`` is the older one-shot command: it runs ``+exp=designer`` into ``--out``
(``--runs`` its ``retrain.runs``, ``--robots`` ``retrain.robots``, ``--seeds`` and
``--confirm`` theirs, ``--budget`` and ``--arena`` short for ``learner.total_steps=`` and
``env=``, ``--jobs`` the executor's workers; any other override goes as it would to
``evo/main.py``), then writes the comparison. Without ``--arena`` (or ``env=``) the
robots train in the arena the GA runs evolved in (their ``config.yaml``), when they all
agree; else in the config's (clean). ``--runs`` takes GA run directories or folders
holding them; each run's best robot enters under the run's name (``E+L_seed0``), every
robot file of ``--robots`` under its file name (``four_wheeler``).

Into the folder (beside the retraining's ``trainings.csv``, one row per training,
``confirmation`` true for the confirmation's, ``robots/`` and ``evals/``):

* ``comparison.csv``: per robot, the mean over seeds with a 95 % t-interval, and the
  worst seed, of each metric;
* ``per_method.csv``: per method (each GA run's method, ``designed`` for the hand-made
  robots), the mean over its robots with a 95 % t-interval over robots: one robot per GA
  run, so the run is the unit (``comparison.md`` adds the evolved methods' differences);
* ``head_to_head.csv`` and ``comparison.md``: the best evolved robot against the best
  hand-made one (best: the highest mean evaluation return over seeds), the differences
  with Welch 95 % intervals over seeds, and a one-line verdict;
* ``comparison.png``: every robot's metrics with their intervals, by origin, the two
  chosen ringed; ``chosen.png``: pictures of the two chosen robots (MuJoCo's offscreen
  renderer: ``MUJOCO_GL=egl``; when it cannot render, the report's notes say why).

**Selection bias and the confirmation.** Each side's best is the robot that did best in
these same trainings, so its mean is biased upwards, the more so the more robots a side
has. With ``retrain.confirm=C`` (``--confirm C``) the two chosen robots are trained again
under fresh seeds ``seeds .. seeds+C-1`` and the verdict comes from those trainings
alone (the choice made on seeds ``0 .. seeds-1`` cannot favour either side there).

A comparison folder made before the trainings were evo's (``trainings/<robot>_seed<s>/``
beside a ``trainings.csv`` of the columns below) reads the same way.
"""

from __future__ import annotations

import argparse
import json
import math
import shlex
import sys
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, Literal

import numpy as np
import pandas as pd
from omegaconf import DictConfig, OmegaConf

from analysis.evo_task import run_evo
from analysis.load import find_run_dirs
from analysis.markdown import figure_link, fmt_ci, fmt_number, markdown_table, safe_name
from analysis.stats import mean_interval, welch_contrast
from evo.run.layout import RetrainLayout, RunLayout
from evo.run.records import read_retrain_settings

if TYPE_CHECKING:
    from evo.robot import Limits
    from evo.robot.builder import PhysicsParams

Origin = Literal["evolved", "designed"]
METRICS: dict[str, str] = {
    "success_rate": "higher",
    "eval_mean_return": "higher",
    "eval_time_to_target": "lower",
}
"""The compared metrics of the deterministic evaluation, and which way is better."""
RANGES: dict[str, tuple[float, float]] = {
    "success_rate": (0.0, 1.0),
    "eval_time_to_target": (0.0, math.inf),
}
"""What a metric can be: a per-robot interval is clipped to it (a t-interval over three
seeds of a success rate can reach past 1)."""
TRAINING_COLUMNS = ("robot", "origin", "method", "run", "structure", "seed", "arena", "env_steps",
                    "fitness", "success_rate", "eval_mean_return", "eval_time_to_target",
                    "eval_episodes", "wall_seconds")
"""The columns of ``trainings.csv`` the comparison reads: ``robot`` the label compared
(run name or file name), ``method`` the GA run's method (``E+L``, ``E+L+I``, ...;
``designed`` for a hand-made robot), ``run`` the GA run it came from ("" for a hand-made
one), ``structure`` the robot's name, ``eval_time_to_target`` simulated seconds (empty
when no episode reached the target), ``wall_seconds`` the training's wall time; the file
adds ``confirmation``."""
NOISY = ("stochastic_success_rate", "stochastic_mean_return")
"""The noisy policy's evaluation beside the deterministic one, read when the file has it
(a folder trained before it existed does not)."""
CONFIDENCE = 0.95
COMPARISON_FIGURE, CHOSEN_FIGURE = "comparison.png", "chosen.png"
TRAININGS, COMPARISON, HEAD_TO_HEAD, PER_METHOD, REPORT, SETTINGS = (
    "trainings.csv", "comparison.csv", "head_to_head.csv", "per_method.csv", "comparison.md",
    "settings.json")
"""The files of a comparison folder."""


class DesignerError(ValueError):
    """A bad argument, run directory or comparison folder; the message names it."""


# ---------------------------------------------------------------- the folder


def robot_file(out: Path, label: str) -> Path:
    """``<out>/robots/<robot>.json``: the robot compared under ``label``."""
    return out / "robots" / f"{safe_name(label)}.json"


def read_trainings(folder: Path) -> tuple[pd.DataFrame, pd.DataFrame]:
    """The finished trainings of a comparison folder: the compared ones and the
    confirmation's, each with :data:`TRAINING_COLUMNS` (a retraining's random-learner
    trainings, if any, left out).

    Raises:
        DesignerError: For a folder without trainings.
    """
    path = folder / TRAININGS
    try:
        table = pd.read_csv(path)
    except (OSError, pd.errors.EmptyDataError) as err:
        raise DesignerError(f"{path}: no trainings to compare ({err!r})") from None
    if "role" in table:
        table = table[table["role"] == "seed"]
    missing = [c for c in TRAINING_COLUMNS if c not in table]
    if missing:
        raise DesignerError(f"{path}: not a comparison's trainings (no {', '.join(missing)})")
    confirmation = (table["confirmation"].astype(bool) if "confirmation" in table
                    else pd.Series(False, index=table.index))
    columns = [*TRAINING_COLUMNS, *(c for c in NOISY if c in table and table[c].notna().any())]
    return (table.loc[~confirmation, columns].reset_index(drop=True),
            table.loc[confirmation, columns].reset_index(drop=True))


def _run_arena(run_dir: Path) -> str:
    """``env.name`` of a run's ``config.yaml``; "" when it does not say."""
    path = RunLayout(run_dir).config
    try:
        name = OmegaConf.select(OmegaConf.load(path), "env.name") if path.is_file() else None
    except Exception:  # noqa: BLE001 - an unreadable config only loses the label
        name = None
    return "" if name is None else str(name)


def _notes(folder: Path, trainings: pd.DataFrame, arena: str) -> list[str]:
    """What the report notes of a folder: robots that evolved in another arena, and
    trainings its settings plan that have not finished."""
    notes = []
    for run in trainings.loc[trainings["origin"] == "evolved", "run"].drop_duplicates():
        label = trainings.loc[trainings["run"] == run, "robot"].iloc[0]
        evolved_in = _run_arena(Path(str(run)))
        if evolved_in and evolved_in != arena:
            notes.append(f"{label} evolved in the {evolved_in} arena, not the {arena} one")
    settings = read_retrain_settings(RetrainLayout(folder).settings)
    if settings is not None and settings.first_seed is not None:
        done = set(zip(trainings["robot"], trainings["seed"], strict=True))
        notes += [f"failed (run the same command again to retry): {label} seed {seed}"
                  for label in settings.labels
                  for seed in range(settings.first_seed, settings.first_seed + settings.seeds)
                  if (label, seed) not in done]
    return notes


# ---------------------------------------------------------------- statistics


def mean_ci(values: Sequence[float] | np.ndarray) -> tuple[float, float, float, int]:
    """The mean of the finite ``values`` with its 95 % t-interval over them
    (:func:`analysis.stats.mean_interval`).

    Returns:
        ``(mean, low, high, n)``; the interval is NaN for fewer than 2 values, and the
        mean itself when they are all equal.
    """
    x = np.asarray(values, dtype=float)
    n = int(np.isfinite(x).sum())
    interval = mean_interval(x, CONFIDENCE)
    return interval.estimate, interval.ci_low, interval.ci_high, n


def welch_difference(a: Sequence[float] | np.ndarray, b: Sequence[float] | np.ndarray
                     ) -> tuple[float, float, float]:
    """``mean(a) − mean(b)`` over the finite values, with Welch's 95 % interval
    (:func:`analysis.stats.welch_contrast`).

    Returns:
        ``(difference, low, high)``; the interval is NaN when a side has fewer than 2
        values, and the difference itself when neither side varies.
    """
    x, y = (np.asarray(v, dtype=float) for v in (a, b))
    x, y = x[np.isfinite(x)], y[np.isfinite(y)]
    if len(x) == 0 or len(y) == 0:
        return math.nan, math.nan, math.nan
    contrast = welch_contrast([x, y], [1.0, -1.0], CONFIDENCE)
    return contrast.estimate, contrast.ci_low, contrast.ci_high


def metric_ci(metric: str, values: np.ndarray) -> tuple[float, float, float, int]:
    """:func:`mean_ci` of a metric's ``values``, its interval clipped to the metric's
    :data:`RANGES` (a NaN bound stays NaN)."""
    mean, low, high, n = mean_ci(values)
    floor, ceiling = RANGES.get(metric, (-math.inf, math.inf))
    return mean, max(low, floor), min(high, ceiling), n


def comparison_table(trainings: pd.DataFrame) -> pd.DataFrame:
    """Per robot, the mean over seeds with its 95 % t-interval (clipped to the metric's
    :data:`RANGES`) and the worst seed of each metric (:data:`METRICS`), best mean
    evaluation return first.

    ``<metric>_seeds`` counts the seeds with a value: for the time to target, the seeds
    under which some evaluation episode reached the target.
    """
    rows = []
    for (robot, origin), group in trainings.groupby(["robot", "origin"], sort=False):
        row: dict[str, object] = {"robot": robot, "origin": origin,
                                  "method": group["method"].iloc[0]
                                  if "method" in group else origin,  # an older table
                                  "run": group["run"].iloc[0],
                                  "structure": group["structure"].iloc[0],
                                  "seeds": len(group)}
        for metric, better in METRICS.items():
            values = group[metric].to_numpy(dtype=float)
            mean, low, high, n = metric_ci(metric, values)
            worst = (np.nanmin if better == "higher" else np.nanmax)(values) if n else math.nan
            row |= {f"{metric}_mean": mean, f"{metric}_low": low, f"{metric}_high": high,
                    f"{metric}_worst": float(worst), f"{metric}_seeds": n}
        if NOISY[0] in group:  # the policy with its noise, on the same episodes
            noisy = group[NOISY[0]].to_numpy(dtype=float)
            row |= {f"{NOISY[0]}_mean": float(np.nanmean(noisy)),
                    f"{NOISY[0]}_worst": float(np.nanmin(noisy))}
        row["fitness_mean"] = float(group["fitness"].mean())
        row["wall_seconds_mean"] = float(group["wall_seconds"].mean())
        rows.append(row)
    table = pd.DataFrame(rows)
    if table.empty:
        return table
    return table.sort_values("eval_mean_return_mean", ascending=False, kind="stable",
                             ignore_index=True)


def per_method(comparison: pd.DataFrame) -> pd.DataFrame:
    """Per method (the GA runs' methods, and ``designed``), the mean over its robots of
    each robot's mean over seeds, with a 95 % t-interval over robots: for the evolved
    methods one robot per GA run, so the run is the unit (with and without inheritance
    compared on the bodies their runs chose, each trained from scratch).

    Returns:
        One row per method: ``method``, ``robots``, and ``<metric>_mean/_low/_high``.
    """
    rows = []
    for method, group in comparison.groupby("method", sort=False):
        row: dict[str, object] = {"method": method, "robots": len(group)}
        for metric in METRICS:
            mean, low, high, _ = metric_ci(metric, group[f"{metric}_mean"].to_numpy(dtype=float))
            row |= {f"{metric}_mean": mean, f"{metric}_low": low, f"{metric}_high": high}
        rows.append(row)
    return pd.DataFrame(rows)


def method_differences(comparison: pd.DataFrame) -> pd.DataFrame:
    """Every pair of evolved methods (``E+L+I`` − ``E+L``, ...): the difference of their
    robots' means over seeds on each metric, with Welch's 95 % interval over robots (GA
    runs). Empty with fewer than two evolved methods."""
    evolved = comparison[comparison["origin"] == "evolved"]
    methods = sorted(evolved["method"].unique(), key=lambda m: (len(m), m), reverse=True)
    rows = []
    for i, a in enumerate(methods):
        for b in methods[i + 1:]:
            for metric in METRICS:
                diff, low, high = welch_difference(
                    evolved.loc[evolved["method"] == a, f"{metric}_mean"].to_numpy(dtype=float),
                    evolved.loc[evolved["method"] == b, f"{metric}_mean"].to_numpy(dtype=float))
                rows.append(dict(pair=f"{a} − {b}", metric=metric, difference=diff, low=low,
                                 high=high))
    return pd.DataFrame(rows, columns=["pair", "metric", "difference", "low", "high"])


def best_of(comparison: pd.DataFrame, origin: Origin) -> str | None:
    """The robot of ``origin`` with the highest mean evaluation return; None if none."""
    rows = comparison[comparison["origin"] == origin]
    return None if rows.empty else str(rows.iloc[0]["robot"])  # sorted best first


def head_to_head(trainings: pd.DataFrame, evolved: str, designed: str) -> pd.DataFrame:
    """``evolved`` against ``designed`` on every metric: the means, the difference
    (evolved − designed) with Welch's 95 % interval over seeds, and which is better."""
    rows = []
    for metric, better in METRICS.items():
        a = trainings.loc[trainings["robot"] == evolved, metric].to_numpy(dtype=float)
        b = trainings.loc[trainings["robot"] == designed, metric].to_numpy(dtype=float)
        diff, low, high = welch_difference(a, b)
        clear = low > 0 if better == "higher" else high < 0  # False for a NaN interval
        rows.append(dict(metric=metric, better=better, evolved=float(np.nanmean(a))
                         if np.isfinite(a).any() else math.nan,
                         designed=float(np.nanmean(b)) if np.isfinite(b).any() else math.nan,
                         difference=diff, low=low, high=high, evolved_clearly_better=clear))
    return pd.DataFrame(rows)


def _by(row: pd.Series) -> str:
    """A difference with its interval: ``+0.120 [+0.050, +0.190]``."""
    diff, low, high = float(row["difference"]), float(row["low"]), float(row["high"])
    return f"{diff:+.3f} [{low:+.3f}, {high:+.3f}]" if not math.isnan(low) else f"{diff:+.3f}"


def verdict(duel: pd.DataFrame, evolved: str, designed: str, arena: str) -> str:
    """One line: whether ``evolved`` beats ``designed`` on mean evaluation return (its
    Welch interval above 0), and by how much (and the success rate's difference)."""
    rows = duel.set_index("metric")
    row = rows.loc["eval_mean_return"]
    low, high = float(row["low"]), float(row["high"])
    if not math.isnan(low) and low > 0:
        word = "beats"
    elif not math.isnan(high) and high < 0:
        word = "does not beat (it is beaten by)"
    else:
        word = "does not clearly beat"
    return (f"{evolved} (evolved) {word} {designed} (hand-made) in the {arena} arena: "
            f"evaluation return {_by(row)}, success rate {_by(rows.loc['success_rate'])} "
            "(evolved − hand-made, Welch 95 % CI over seeds)")


# ---------------------------------------------------------------- the report


@dataclass(frozen=True)
class Report:
    """What a comparison folder's report is written from."""

    trainings: pd.DataFrame
    comparison: pd.DataFrame
    duel: pd.DataFrame | None
    verdict: str
    confirm_trainings: pd.DataFrame | None
    confirmed_duel: pd.DataFrame | None
    arena: str
    budget: int
    seeds: int
    command: str
    notes: tuple[str, ...]


def build_report(trainings: pd.DataFrame, *, arena: str, budget: int, seeds: int,
                 command: str, notes: Sequence[str] = (),
                 confirmation: pd.DataFrame | None = None) -> Report:
    """The per-robot table, the head-to-head of the best of each origin and its verdict:
    from ``confirmation`` (the chosen two's trainings under fresh seeds, as
    :func:`collect` gives them) when it holds both, else from ``trainings`` (biased
    towards the chosen: see the module)."""
    comparison = comparison_table(trainings)
    evolved = best_of(comparison, "evolved") if not comparison.empty else None
    designed = best_of(comparison, "designed") if not comparison.empty else None
    if evolved is None or designed is None:
        missing = "evolved" if evolved is None else "hand-made"
        return Report(trainings, comparison, None, f"no head-to-head: no {missing} robot "
                      "has a finished training", None, None, arena, budget, seeds, command,
                      tuple(notes))
    duel = head_to_head(trainings, evolved, designed)
    confirmed = None
    if confirmation is not None and {evolved, designed} <= set(confirmation["robot"]):
        confirmed = head_to_head(confirmation, evolved, designed)
    judged = duel if confirmed is None else confirmed
    return Report(trainings, comparison, duel, verdict(judged, evolved, designed, arena),
                  confirmation, confirmed, arena, budget, seeds, command, tuple(notes))


def write_report(out: Path, report: Report) -> Report:
    """``comparison.csv``, ``per_method.csv``, ``head_to_head.csv``, the figures
    (:func:`write_figures`) and ``comparison.md``.

    Returns:
        The report as written: its notes add why a figure is missing.
    """
    from evo.run.files import write_csv, write_text

    write_csv(out / COMPARISON, report.comparison)
    if not report.comparison.empty:
        write_csv(out / PER_METHOD, per_method(report.comparison))
    if report.duel is not None:
        duels = [report.duel.assign(seeds="choice")]
        if report.confirmed_duel is not None:
            duels.append(report.confirmed_duel.assign(seeds="confirmation"))
        write_csv(out / HEAD_TO_HEAD, pd.concat(duels, ignore_index=True))
    figures, notes = write_figures(out, report.comparison, report.arena,
                                   figure=out / COMPARISON_FIGURE, pictures=out / CHOSEN_FIGURE)
    report = replace(report, notes=(*report.notes, *notes))
    write_text(out / REPORT, _markdown(report, out, figures))
    return report


# ---------------------------------------------------------------- the figures


def write_figures(folder: Path, comparison: pd.DataFrame, arena: str, *, figure: Path,
                  pictures: Path) -> tuple[list[Path], list[str]]:
    """The comparison's figures: ``figure``, every robot's metrics with their intervals
    (:func:`analysis.plots.plot_designer`), and ``pictures``, the best evolved robot
    (left) and the best hand-made one (right), read from ``folder``'s robot files and
    built with its settings' physics.

    Args:
        folder: The comparison folder (its ``robots/`` and ``settings.json``).
        comparison: :func:`comparison_table` (or its ``comparison.csv``).
        arena: The arena, for the title.
        figure: The PNG of the metrics.
        pictures: The PNG of the two robots.

    Returns:
        The figures written (none for an empty table), and a note for each that could
        not be (no OpenGL to render with, a robot file unreadable), saying why.
    """
    from analysis.plots import plot_designer
    from evo.robot.render import RenderError

    if comparison.empty:
        return [], []
    chosen = [r for r in (best_of(comparison, "evolved"), best_of(comparison, "designed"))
              if r is not None]
    plot_designer(comparison, chosen=chosen, path=figure, title=(
        f"Evolved against hand-made robots, {arena} arena: mean over seeds, 95 % CI"))
    if len(chosen) < 2:
        return [figure], []
    try:
        chosen_pictures(folder, comparison, chosen, pictures)
    except (RenderError, OSError, ValueError, KeyError) as err:
        return [figure], [f"no pictures of the chosen robots ({pictures.name}): {err}"]
    return [figure, pictures], []


def chosen_pictures(folder: Path, comparison: pd.DataFrame, chosen: Sequence[str],
                    path: Path) -> Path:
    """Pictures of the robots ``chosen`` side by side, each titled with its label and
    origin, and its mean success rate and evaluation return over seeds.

    Raises:
        evo.robot.render.RenderError: No OpenGL backend works (``MUJOCO_GL=egl``).
        OSError, ValueError: An unreadable robot file or ``settings.json``.
    """
    from analysis.plots import ORIGIN_LABELS
    from evo.robot import load_robot
    from evo.robot.gallery import contact_sheet

    limits, physics = _folder_physics(folder)
    robots = [load_robot(robot_file(folder, label), limits) for label in chosen]
    rows = comparison.set_index("robot")
    titles = []
    for label in chosen:
        row = rows.loc[label]
        titles.append(f"{label} ({ORIGIN_LABELS[str(row['origin'])]})\nsuccess "
                      f"{fmt_number(row['success_rate_mean'], 2)}, eval return "
                      f"{fmt_number(row['eval_mean_return_mean'], 2)}")
    return contact_sheet(robots, physics, path, titles=titles)


def _folder_physics(folder: Path) -> tuple[Limits, PhysicsParams]:
    """The robot limits and module constants a comparison folder trained with (its
    ``settings.json``; the defaults for a folder without one)."""
    from evo.config import typed
    from evo.robot import Limits
    from evo.robot.builder import PhysicsParams

    path = folder / SETTINGS
    if not path.is_file():
        return Limits(), PhysicsParams()
    try:
        cfg = OmegaConf.create(str(json.loads(path.read_text())["config"]))
    except (json.JSONDecodeError, KeyError) as err:
        raise ValueError(f"{path}: no readable config ({err!r})") from None
    if not isinstance(cfg, DictConfig):
        raise ValueError(f"{path}: its config is not a mapping")
    return (typed(Limits, OmegaConf.select(cfg, "morphology.limits"), "morphology.limits"),
            typed(PhysicsParams, OmegaConf.select(cfg, "morphology.physics"),
                  "morphology.physics"))


def folder_arena(folder: Path) -> str:
    """The arena a comparison folder's robots trained in (its ``trainings.csv``).

    Raises:
        DesignerError: For a folder without trainings, or trained in several arenas.
    """
    path = folder / TRAININGS
    try:
        arenas: list[str] = sorted({str(a) for a in pd.read_csv(path)["arena"]})
    except (OSError, KeyError, pd.errors.EmptyDataError) as err:
        raise DesignerError(f"{path}: no trainings to read the arena from ({err!r})") from None
    if len(arenas) != 1:
        raise DesignerError(f"{path}: expected one arena, found {arenas or 'none'}")
    return arenas[0]


def _per_robot_markdown(comparison: pd.DataFrame) -> pd.DataFrame:
    """The per-robot table as the report shows it: estimates with their intervals."""
    shown = pd.DataFrame({"robot": comparison["robot"], "origin": comparison["origin"],
                          "seeds": comparison["seeds"]})
    for metric, title in (("success_rate", "success"), ("eval_mean_return", "eval return"),
                          ("eval_time_to_target", "time to target (s)")):
        shown[title] = [fmt_ci(r[f"{metric}_mean"], r[f"{metric}_low"], r[f"{metric}_high"])
                        for _, r in comparison.iterrows()]
        shown[f"worst {title}"] = comparison[f"{metric}_worst"]
        if metric == "success_rate" and f"{NOISY[0]}_mean" in comparison:
            shown["success with noise"] = comparison[f"{NOISY[0]}_mean"]
            shown["worst success with noise"] = comparison[f"{NOISY[0]}_worst"]
    shown["seeds reaching"] = comparison["eval_time_to_target_seeds"]
    return shown


def _per_method_markdown(comparison: pd.DataFrame) -> list[str]:
    """The section on methods: each method's robots together, and the evolved methods'
    differences; nothing without an evolved robot."""
    if comparison.empty or not (comparison["origin"] == "evolved").any():
        return []
    methods = per_method(comparison)
    shown = pd.DataFrame({"method": methods["method"], "robots": methods["robots"]})
    for metric, title in (("success_rate", "success"), ("eval_mean_return", "eval return"),
                          ("eval_time_to_target", "time to target (s)")):
        shown[title] = [fmt_ci(r[f"{metric}_mean"], r[f"{metric}_low"], r[f"{metric}_high"])
                        for _, r in methods.iterrows()]
    lines = [
        "## Per method (one robot per GA run: the run is the unit)\n",
        "Each GA run's best robot, retrained from scratch: the mean over a method's robots "
        "of each robot's mean over seeds, with a 95 % t-interval over robots. This judges "
        "the bodies the runs chose, every one trained the same way, whatever the run's "
        "robots started from (a run with inheritance included).\n",
        markdown_table(shown),
    ]
    differences = method_differences(comparison)
    if not differences.empty:
        lines += ["Differences between the evolved methods (Welch 95 % intervals over "
                  "robots):\n", markdown_table(differences)]
    return lines


def _markdown(report: Report, out: Path, figures: Sequence[Path] = ()) -> str:
    """``comparison.md``, linking the ``figures`` written into ``out``."""
    links = {path.name: path for path in figures}
    lines = [
        "# Evolution against the designer\n",
        f"`{report.command}`\n",
        f"Every robot retrained from scratch as `+exp=train` does, in the **{report.arena}** "
        f"arena, {report.budget:,} env steps per training, seeds 0..{report.seeds - 1}; "
        "each training then evaluated deterministically (the policy's mean action). Per "
        "robot: the mean over seeds with its 95 % t-interval over seeds (clipped to "
        "what the metric can be: a success rate to [0, 1], a time to 0 and above), and the "
        "worst seed. Time to target: mean simulated seconds to reach the target over the "
        "evaluation episodes that reached it, averaged over the seeds under which some "
        "episode did (`seeds reaching`).\n",
        "## Per robot (best mean evaluation return first)\n",
        markdown_table(_per_robot_markdown(report.comparison)) if not report.comparison.empty
        else "_(no training finished yet)_\n",
    ]
    if COMPARISON_FIGURE in links:
        lines.append(figure_link(links[COMPARISON_FIGURE], out, "every robot's success rate, "
                                 "evaluation return and time to target with 95 % intervals; "
                                 "the chosen two ringed"))
    lines += _per_method_markdown(report.comparison)
    lines.append("## Head to head\n")
    if CHOSEN_FIGURE in links:
        lines.append(figure_link(links[CHOSEN_FIGURE], out,
                                 "the best evolved robot (left) and the best hand-made one"))
    if report.duel is not None:
        lines += [
            "The best evolved robot against the best hand-made one, best meaning the "
            "highest mean evaluation return over seeds. Differences are evolved − hand-made "
            "with Welch 95 % intervals over seeds (for the time to target, lower is "
            "better).\n",
            markdown_table(report.duel),
        ]
    if report.confirmed_duel is not None and report.confirm_trainings is not None:
        fresh = sorted(set(report.confirm_trainings["seed"]))
        lines += [
            f"### Confirmation under fresh seeds {', '.join(map(str, fresh))}\n",
            "The same two robots trained again under seeds the choice did not see; the "
            "verdict is read here.\n",
            markdown_table(report.confirmed_duel),
        ]
    lines += [
        f"**Verdict:** {report.verdict}.\n",
        "Selection bias: each side's best is the robot that did best in these same "
        "retrainings, so its mean is biased upwards (the more robots a side has, the more "
        "so), and the interval of the difference does not account for the choice. "
        + ("The verdict is therefore read from the confirmation under fresh seeds.\n"
           if report.confirmed_duel is not None else
           "A confirmation (`--confirm C`) retrains the two chosen robots under fresh "
           "seeds and reads the verdict there.\n"),
    ]
    if report.notes:
        lines += ["## Notes\n", *(f"- {note}" for note in report.notes), ""]
    return "\n".join(lines)


# ---------------------------------------------------------------- CLI


def report_folder(folder: Path, *, command: str | None = None) -> Report:
    """Write the comparison of the folder's finished trainings (``comparison.md`` and
    its tables and figures).

    Args:
        folder: A comparison folder (``+exp=designer``'s ``hydra.run.dir``).
        command: The command the report names; by default the retraining's.

    Raises:
        DesignerError: For a folder without trainings, or trained in several arenas.
    """
    trainings, confirmation = read_trainings(folder)
    arena = folder_arena(folder)
    settings = read_retrain_settings(RetrainLayout(folder).settings)
    budget = (settings.budget if settings is not None and settings.first_seed is not None
              else int(trainings["env_steps"].min()))
    seeds = int(trainings.groupby("robot")["seed"].nunique().max())
    if command is None:
        command = ("python evo/main.py " + " ".join(settings.overrides)
                   if settings is not None and settings.first_seed is not None
                   else f"python -m analysis.designer {folder}")
    report = build_report(trainings, arena=arena, budget=budget, seeds=seeds,
                          command=command, notes=_notes(folder, trainings, arena),
                          confirmation=confirmation if len(confirmation) else None)
    return write_report(folder, report)


def parse_args(argv: Sequence[str]) -> argparse.Namespace:
    """The command line: a folder to compare, or the older one-shot options."""
    if argv and not argv[0].startswith("-") and "=" not in argv[0]:
        report = argparse.ArgumentParser(
            prog="python -m analysis.designer",
            description="Compare the retrained robots of a folder (python evo/main.py "
                        "+exp=designer). With --runs/--robots/--out instead: run the "
                        "retraining first (the older command line).")
        report.add_argument("folder", type=Path, help="the comparison's folder")
        args = report.parse_args(argv)
        args.out = None
        return args
    cli = argparse.ArgumentParser(
        prog="python -m analysis.designer",
        description="Retrain the best robot of each GA run and every hand-made robot "
                    "under +exp=train's protocol with several seeds (python evo/main.py "
                    "+exp=designer), and compare them.")
    cli.add_argument("--runs", type=Path, nargs="*", default=[],
                     help="GA run directories or folders of them (their best robots)")
    cli.add_argument("--robots", type=Path, default=Path("robots"),
                     help="folder of hand-made evo.robot/1 files (default: robots/)")
    cli.add_argument("--out", type=Path, required=True, help="output folder")
    cli.add_argument("--seeds", type=int, default=3, help="trainings per robot (seeds 0..S-1)")
    cli.add_argument("--budget", type=int, default=None,
                     help="env steps per training (learner.total_steps; +exp=train: 150000)")
    cli.add_argument("--arena", choices=("clean", "cluttered"), default=None,
                     help="the arena (env=...; default: the one the runs evolved in, "
                          "else the config's: clean)")
    cli.add_argument("--confirm", type=int, default=0, metavar="C",
                     help="train the best evolved and best hand-made robot again under C "
                          "fresh seeds and judge them there (default 0: no confirmation)")
    cli.add_argument("--jobs", type=int, default=1, help="trainings run at a time")
    cli.add_argument("overrides", nargs="*",
                     help="config overrides as for python evo/main.py +exp=train")
    args = cli.parse_args(argv)
    if args.seeds < 2:
        cli.error(f"--seeds: expected at least 2 (an interval over seeds), got {args.seeds}")
    if args.confirm == 1 or args.confirm < 0:
        cli.error(f"--confirm: expected 0 or at least 2 fresh seeds, got {args.confirm}")
    if args.jobs < 1:
        cli.error(f"--jobs: expected at least 1, got {args.jobs}")
    if args.budget is not None and args.budget < 1:
        cli.error(f"--budget: expected a positive env-step count, got {args.budget}")
    args.folder = None
    return args


def _quoted(path: Path) -> str:
    """A path as a quoted string of Hydra's override grammar."""
    return "'" + str(path).replace("\\", "\\\\").replace("'", "\\'") + "'"


def designer_overrides(args: argparse.Namespace, log: Callable[[str], None] = print
                       ) -> list[str]:
    """The ``+exp=designer`` command line that the older options stand for."""
    runs = ",".join(_quoted(p) for p in args.runs)
    return ["+exp=designer", f"retrain.runs=[{runs}]", f"retrain.robots={_quoted(args.robots)}",
            f"retrain.seeds={args.seeds}", f"retrain.confirm={args.confirm}",
            f"executor.workers={args.jobs}",
            *(["env=" + args.arena] if args.arena else []),
            *([f"learner.total_steps={args.budget}"] if args.budget else []),
            *runs_arena(args.runs, args.overrides if args.arena is None else ["env="], log),
            f"hydra.run.dir={args.out}", *args.overrides]


FLAGS = {"retrain.runs": "--runs", "retrain.robots": "--robots", "retrain.seeds": "--seeds",
         "retrain.confirm": "--confirm", "hydra.run.dir": "--out"}
"""The older command line's name of each key that a message may name."""


def _as_flags(message: str) -> str:
    for key, flag in FLAGS.items():
        message = message.replace(key, flag)
    return message


def runs_arena(runs: Sequence[Path], overrides: Sequence[str],
               log: Callable[[str], None] = print) -> list[str]:
    """``env=<arena>`` of the GA runs when no override chooses the env and every run
    evolved in the same arena of ``conf/env``; nothing otherwise."""
    if not runs or any(o.startswith(("env=", "+env=")) for o in overrides):
        return []
    try:
        arenas = {_run_arena(d) for d in find_run_dirs(list(runs))}
    except (OSError, ValueError) as err:
        raise DesignerError(f"--runs: {err}") from None
    arena = arenas.pop() if len(arenas) == 1 else ""
    if not (arena and (CONF_ENV / f"{arena}.yaml").is_file()):
        return []
    log(f"arena: {arena}, where the runs evolved (--arena to choose another)")
    return [f"env={arena}"]


CONF_ENV = Path(__file__).resolve().parents[1] / "conf" / "env"
"""The arenas of ``conf/env``."""


def main(argv: Sequence[str] | None = None) -> int:
    """Compare a folder, or (the older command line) run the retraining and then
    compare; exit 0, 2 with one line naming a bad argument, config key or folder in
    use, 1 when a training failed (the report holds the others), the task's 130 or 143
    when interrupted (run the same command again to continue)."""
    given = sys.argv[1:] if argv is None else list(argv)
    args = parse_args(given)
    folder, command = args.folder, None
    try:
        if folder is None:
            status = run_evo(designer_overrides(args), rename=_as_flags)
            if status != 0:
                return status
            folder = args.out
            command = "python -m analysis.designer " + shlex.join(given)
        report = report_folder(folder, command=command)
    except DesignerError as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    print(f"{report.verdict}\nreport: {folder / REPORT}")
    return 1 if any(n.startswith("failed") for n in report.notes) else 0


if __name__ == "__main__":
    sys.exit(main())
