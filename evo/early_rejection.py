"""Early rejection (SPEC §5 extension, paper §8–§9): stop training an offspring whose
learning curve says it cannot enter the population.

In the steady-state GA an offspring matters only if its fitness beats the population's
minimum (replace-worst-if-better). :class:`EarlyRejection` (``ga.early_rejection``) sets
checkpoints (fractions of the offspring's budget), a predictor and a margin; at each
checkpoint :class:`StoppingRule` predicts the offspring's final fitness from its curve
so far and asks training to stop when ``prediction + margin`` is below the minimum it
has to beat. It is off in every paper config.

The predictors are the early-slope study's (``analysis.early_slope``, which imports
them from here), computed from a curve's informative batches (those that completed
episodes):

* ``value``: mean return of the episodes of the last ``last`` informative batches;
* ``area``: the prefix's time-averaged return (trapezoidal area over its span);
* ``curve``: ``a − b·exp(−c·τ)`` (``τ = env_steps / budget``) fitted to the prefix and
  evaluated at ``τ = 1``;
* ``slope``: Theil–Sen slope of the second half of the prefix (per 1,000 env steps; not
  on the return scale, so no rule uses it alone);
* ``rate``: the return of an episode that ran the task's ``t_max`` control steps at the
  reward rate of the last ``last`` batches (their summed ``train/reward/<term>`` means
  per env step, recorded for every batch). It needs no finished episode: where episodes
  run to ``t_max`` (the robots a rule stops) it is their return at that rate, and where
  they end early in success it overstates it, so it errs towards training on.

scipy is imported inside the functions that use it: it is the slowest import on the path
of ``evo/main.py``, which loads this module whether or not the run uses it.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pandas as pd
from numpy.typing import ArrayLike, NDArray

SLOPE_STEPS = 1_000
"""The slope predictor is in return per this many env steps."""
RATE_BOUNDS = (0.1, 100.0)
"""Bounds of the saturating curve's rate ``c`` (per budget): from nearly linear over the
whole budget to saturated within its first percent."""

# ---------------------------------------------------------------- one robot's curve


_EMPTY = np.zeros(0)


@dataclass(frozen=True)
class Curve:
    """One robot's informative batches (those that completed episodes), in step order,
    and the reward rate of every batch.

    Attributes:
        steps: Env steps at each informative batch.
        returns: Mean return of the episodes that ended in it.
        episodes: How many ended in it.
        rate_steps: Env steps at every batch (informative or not).
        rates: Reward per env step of every batch, all terms summed (empty for a
            curve recorded without its ``train/reward/<term>`` columns).
    """

    steps: NDArray[np.float64]
    returns: NDArray[np.float64]
    episodes: NDArray[np.float64]
    rate_steps: NDArray[np.float64] = field(default_factory=lambda: _EMPTY)
    rates: NDArray[np.float64] = field(default_factory=lambda: _EMPTY)

    @classmethod
    def from_rows(cls, rows: pd.DataFrame) -> Curve:
        """Build from one robot's rows of a curves table: its informative batches, and
        every batch's reward rate where the table has the reward terms."""
        rows = rows.sort_values("env_steps")
        done = rows[(rows["train/episodes"] > 0) & np.isfinite(rows["train/mean_return"])]
        terms = [c for c in rows.columns if str(c).startswith("train/reward/")]
        rated = rows.dropna(subset=terms) if terms else rows.iloc[:0]
        return cls(done["env_steps"].to_numpy(dtype=float),
                   done["train/mean_return"].to_numpy(dtype=float),
                   done["train/episodes"].to_numpy(dtype=float),
                   rated["env_steps"].to_numpy(dtype=float),
                   rated[terms].sum(axis=1).to_numpy(dtype=float) if terms else _EMPTY)

    def select(self, mask: NDArray[np.bool_]) -> Curve:
        """The informative batches where ``mask`` holds (the reward rates as they are)."""
        return Curve(self.steps[mask], self.returns[mask], self.episodes[mask],
                     self.rate_steps, self.rates)

    def prefix(self, cut: float) -> Curve:
        """The batches at or before ``cut`` env steps."""
        done, rated = self.steps <= cut, self.rate_steps <= cut
        return Curve(self.steps[done], self.returns[done], self.episodes[done],
                     self.rate_steps[rated], self.rates[rated])

    def after(self, cut: float) -> Curve:
        """The batches after ``cut`` env steps."""
        return self.select(self.steps > cut)

    def episode_mean(self) -> float:
        """Mean return over all episodes of these batches; NaN when there are none."""
        if self.episodes.sum() <= 0:
            return np.nan
        return float(np.average(self.returns, weights=self.episodes))


def value_at_cut(prefix: Curve, last: int = 3) -> float:
    """Episode-weighted mean return of the last ``last`` batches of ``prefix``."""
    return prefix.select(np.arange(len(prefix.steps)) >= len(prefix.steps) - last).episode_mean()


def rate_at_cut(prefix: Curve, t_max: int, last: int = 3) -> float:
    """``t_max`` times the mean reward per env step of the last ``last`` batches of
    ``prefix``: the return of a ``t_max``-step episode at that rate (NaN without rates)."""
    if len(prefix.rates) == 0:
        return np.nan
    return float(t_max * prefix.rates[-last:].mean())


def late_slope(prefix: Curve, cut: float) -> float:
    """Theil–Sen slope over the second half of the prefix, per :data:`SLOPE_STEPS` steps.

    Returns:
        The slope, or NaN with fewer than two distinct step counts in that half.
    """
    half = prefix.select(prefix.steps >= cut / 2)
    if len(np.unique(half.steps)) < 2:
        return np.nan
    import scipy.stats  # where it is used: see the module's docstring

    return float(scipy.stats.theilslopes(half.returns, half.steps).slope) * SLOPE_STEPS


def prefix_area(prefix: Curve) -> float:
    """Trapezoidal area under the prefix over its span (its time-averaged return)."""
    if len(prefix.steps) == 0:
        return np.nan
    span = prefix.steps[-1] - prefix.steps[0]
    if span == 0:
        return float(prefix.returns.mean())
    import scipy.integrate  # where it is used: see the module's docstring

    return float(scipy.integrate.trapezoid(prefix.returns, prefix.steps) / span)


def saturating(tau: ArrayLike, a: float, b: float, c: float) -> Any:
    """The saturating curve ``a − b·exp(−c·τ)``."""
    return a - b * np.exp(-c * np.asarray(tau, dtype=float))


def _saturating_jacobian(tau: ArrayLike, a: float, b: float, c: float) -> Any:
    e = np.exp(-c * np.asarray(tau, dtype=float))
    return np.column_stack([np.ones_like(e), -e, b * np.asarray(tau) * e])


def _grid_fit(tau: NDArray[np.float64], y: NDArray[np.float64]) -> NDArray[np.float64]:
    """Least-squares ``(a, b, c)`` with ``c`` on a log grid over :data:`RATE_BOUNDS`.

    For a fixed ``c`` the curve is linear in ``a`` and ``b``, so every grid point is a
    two-column least-squares problem; the best one starts :func:`curve_fit`, which
    then cannot wander off into a poor local minimum.
    """
    rates = np.geomspace(*RATE_BOUNDS, 64)
    best: tuple[float, NDArray[np.float64]] = (np.inf, np.array([y.mean(), 0.0, 1.0]))
    for c in rates:
        design = np.column_stack([np.ones_like(tau), -np.exp(-c * tau)])
        coef, *_ = np.linalg.lstsq(design, y, rcond=None)
        sse = float(np.sum((design @ coef - y) ** 2))
        if sse < best[0]:
            best = (sse, np.array([coef[0], coef[1], c]))
    return best[1]


def saturating_extrapolation(prefix: Curve, budget: float, fallback: float) -> float:
    """Fit :func:`saturating` to the prefix and evaluate it at the full budget.

    The fit starts from :func:`_grid_fit` and refines with
    :func:`scipy.optimize.curve_fit` under a soft-L1 loss whose scale is the grid fit's
    robust residual spread; if the refinement fails the grid fit is used.

    Args:
        prefix: Informative prefix of one robot's curve.
        budget: The robot's env-step budget (``τ = env_steps / budget``).
        fallback: Returned when there are fewer than four points.

    Returns:
        The extrapolated mean return at ``τ = 1``.
    """
    tau, y = prefix.steps / budget, prefix.returns
    if len(tau) < 4 or np.ptp(tau) == 0:
        return fallback
    params = _grid_fit(tau, y)
    import scipy.optimize  # where it is used: see the module's docstring

    spread = 1.4826 * np.median(np.abs(saturating(tau, *params) - y))
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", scipy.optimize.OptimizeWarning)
            params, _ = scipy.optimize.curve_fit(
                saturating, tau, y, p0=params, jac=_saturating_jacobian,
                bounds=([-np.inf, -np.inf, RATE_BOUNDS[0]], [np.inf, np.inf, RATE_BOUNDS[1]]),
                loss="soft_l1", f_scale=max(float(spread), 1e-9), max_nfev=200,
            )
    except (RuntimeError, ValueError, np.linalg.LinAlgError):
        pass
    value = float(saturating(1.0, *params))
    return value if np.isfinite(value) else fallback




# ---------------------------------------------------------------- the rule

PREDICTORS = ("value", "area", "curve", "rate")
"""Predictors on the return scale, which a rule can compare with a fitness."""


@dataclass(frozen=True, slots=True)
class EarlyRejection:
    """``ga.early_rejection``: when to stop training an offspring early.

    Attributes:
        enabled: Whether offspring may be stopped early (off in every paper config).
        checkpoints: Fractions of the offspring's budget at which the rule looks
            (calibrated in docs/results/early_rejection/: earlier cuts stop offspring
            that would have entered the population).
        predictor: How the final fitness is predicted from the curve so far: ``value``,
            ``area``, ``curve`` (these three wait for finished episodes) or ``rate``
            (from the first batch on; see the module docstring).
        margin: Fitness units: stop when ``prediction + margin`` is below the population
            minimum the offspring has to beat (larger: fewer wrong rejections).
        last: Batches the ``value`` predictor (informative ones) and the ``rate``
            predictor (any) average.
    """

    enabled: bool = False
    checkpoints: tuple[float, ...] = (0.5,)
    predictor: str = "value"
    margin: float = 0.3
    last: int = 3

    def __post_init__(self) -> None:
        if not self.checkpoints or not all(0 < c < 1 for c in self.checkpoints):
            raise ValueError(f"checkpoints must be fractions of the budget in (0, 1), got "
                             f"{list(self.checkpoints)}")
        if list(self.checkpoints) != sorted(set(self.checkpoints)):
            raise ValueError(f"checkpoints must rise, got {list(self.checkpoints)}")
        if self.predictor not in PREDICTORS:
            raise ValueError(f"predictor must be one of {', '.join(PREDICTORS)}, got "
                             f"{self.predictor!r}")
        if self.margin < 0 or self.last < 1:
            raise ValueError(f"need margin >= 0 and last >= 1, got {self.margin}, {self.last}")


def predict(curve: Curve, budget: float, fraction: float, predictor: str,
            last: int = 3, t_max: int | None = None) -> float:
    """The predicted final fitness of a curve cut at ``fraction`` of ``budget``
    (``t_max``: the task's episode length, which the ``rate`` predictor needs).

    Returns:
        The prediction; NaN when no episode ended before the cut (``rate``: when no
        batch with reward terms came before it).
    """
    cut = fraction * budget
    prefix = curve.prefix(cut)
    if predictor == "rate":
        if t_max is None:
            raise ValueError("the rate predictor needs the task's t_max (control steps "
                             "per episode)")
        return rate_at_cut(prefix, t_max, last)
    value = value_at_cut(prefix, last)
    if predictor == "value":
        return value
    if predictor == "area":
        return prefix_area(prefix)
    if predictor == "curve":
        return saturating_extrapolation(prefix, budget, fallback=value) if np.isfinite(
            value) else value
    raise ValueError(f"unknown predictor {predictor!r}; expected one of {PREDICTORS}")


@dataclass
class Verdict:
    """What the rule decided at a checkpoint."""

    fraction: float
    predicted: float
    threshold: float
    stop: bool


class StoppingRule:
    """The rule for one offspring: call it with every learning-curve row; it returns
    True when training should stop.

    Args:
        config: The rule's settings.
        budget: The offspring's budget, env steps.
        threshold: The population minimum when it was bred, or a function giving the
            current one (an executor that shares the run directory can see the
            population improve while the offspring trains); NaN means nothing to beat.
        t_max: The task's control steps per episode (the ``rate`` predictor's).
    """

    def __init__(self, config: EarlyRejection, budget: int,
                 threshold: float | Callable[[], float], t_max: int | None = None) -> None:
        self.config, self.budget, self.t_max = config, budget, t_max
        self.threshold = threshold if callable(threshold) else (lambda: threshold)
        self.rows: list[Mapping[str, float]] = []
        self.pending = list(config.checkpoints)
        self.verdicts: list[Verdict] = []

    def __call__(self, row: Mapping[str, float]) -> bool:
        self.rows.append(row)
        stop = False
        while self.pending and row["env_steps"] >= self.pending[0] * self.budget:
            fraction = self.pending.pop(0)
            threshold = float(self.threshold())
            curve = Curve.from_rows(pd.DataFrame(self.rows))
            predicted = predict(curve, self.budget, fraction, self.config.predictor,
                                self.config.last, self.t_max)
            stop = bool(np.isfinite(threshold) and np.isfinite(predicted)
                        and predicted + self.config.margin < threshold)
            self.verdicts.append(Verdict(fraction, predicted, threshold, stop))
            if stop:
                break
        return stop

    @property
    def predicted(self) -> float:
        """The latest prediction (NaN before the first checkpoint)."""
        return self.verdicts[-1].predicted if self.verdicts else math.nan


def replay_rule(config: EarlyRejection, curve: Curve, budget: float,
                threshold: float, t_max: int | None = None) -> Verdict | None:
    """The checkpoint at which the rule would have stopped a fully trained curve, or
    None (for calibrating the rule offline on recorded runs)."""
    for fraction in config.checkpoints:
        predicted = predict(curve, budget, fraction, config.predictor, config.last, t_max)
        if np.isfinite(threshold) and np.isfinite(predicted) and (
                predicted + config.margin < threshold):
            return Verdict(fraction, predicted, threshold, True)
    return None
