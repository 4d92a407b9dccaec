"""How many GA seeds per method a run-level test needs to see a difference.

The run-level test (:func:`analysis.ablation.nested.run_level_tests`) compares one mean per run.
A run's mean of ``m`` robots varies between runs with variance
``sd_between² + sd_within² / m`` (:func:`analysis.ablation.nested.variance_components`, per
method). The seeds needed for a difference ``delta`` between two methods come from
statsmodels' two-sample t-test power (:class:`statsmodels.stats.power.TTestIndPower`)
on the run-level effect size ``d = delta / sqrt((var_a + var_b) / 2)``: a closed form,
deterministic, and the equal-``n`` pooled t-test it assumes is close to Welch's when
both methods get the same number of seeds. :func:`simulated_power` checks the answer
with the test the report uses (Welch) on normal run means with each method's own
variance; :func:`seeds_needed` steps up from the closed form until the simulation
agrees.

**Holm over the pairs.** The pair is one of ``n_tests`` in a Holm family. Holm's first
step tests at ``alpha / n_tests``; a pair that comes later is tested at a larger level,
so planning at ``alpha / n_tests`` (Bonferroni) is the level that guarantees the power
whatever the other pairs do.

``python -m analysis.power RUN... [--first N] [--history-only]`` prints the seeds for
the observed E+L − R+L difference of the runs given; ``--pair E+L+I E+L`` for the fifth
arm's question, a test of its own (``n_tests`` 1: :data:`analysis.ablation.nested.EXTRA_PAIRS`).
"""

from __future__ import annotations

import argparse
import math
import sys
import warnings
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import pandas as pd
import scipy.stats
from statsmodels.stats.power import TTestIndPower
from statsmodels.tools.sm_exceptions import ConvergenceWarning

from analysis.ablation.nested import PAIRS, variance_components
from analysis.load import RunDirectoryError, load_histories, load_runs
from analysis.markdown import markdown_table
from analysis.tables import EXTRA_METHODS, fully_trained

MAX_SEEDS = 10_000
"""Seeds per method beyond which :func:`seeds_needed` gives up (returns this)."""


@dataclass(frozen=True)
class RunVariance:
    """A method's spread at the run level.

    Attributes:
        sd_between: Standard deviation of the true run means (the run effect).
        sd_within: Robot-to-robot standard deviation within a run.
    """

    sd_between: float
    sd_within: float

    def of_mean(self, robots_per_run: float) -> float:
        """Variance of a run's mean fitness over ``robots_per_run`` robots."""
        return self.sd_between**2 + self.sd_within**2 / robots_per_run


def analytic_seeds(delta: float, var_a: float, var_b: float, alpha: float,
                   power: float = 0.8) -> int:
    """Seeds per method for a two-sided two-sample t-test (statsmodels), rounded up.

    The smallest ``n`` (at least 2) whose power reaches ``power``: statsmodels'
    ``solve_power``, or a search over its ``power`` where the root finder fails (an
    effect so large that two seeds already suffice, or one out of reach).
    """
    sd = math.sqrt((var_a + var_b) / 2)
    if delta == 0:
        return MAX_SEEDS
    if sd == 0:
        return 2
    size, test = abs(delta) / sd, TTestIndPower()

    def reaches(n: int) -> bool:
        return bool(test.power(effect_size=size, nobs1=n, alpha=alpha, ratio=1.0) >= power)

    if reaches(2):
        return 2
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        n = float(test.solve_power(effect_size=size, alpha=alpha, power=power, ratio=1.0,
                                   alternative="two-sided"))
    if math.isfinite(n):
        return int(min(math.ceil(n), MAX_SEEDS))
    low, high = 2, MAX_SEEDS  # reaches(high) or give up at MAX_SEEDS
    while high - low > 1:
        middle = (low + high) // 2
        low, high = (low, middle) if reaches(middle) else (middle, high)
    return high


def simulated_power(delta: float, var_a: float, var_b: float, n: int, alpha: float,
                    rng: np.random.Generator, reps: int = 4000) -> float:
    """Share of ``reps`` simulated studies in which Welch's test on ``n`` normal run
    means per method (variances ``var_a``, ``var_b``, means ``delta`` apart) rejects."""
    a = delta + math.sqrt(var_a) * rng.standard_normal((reps, n))
    b = math.sqrt(var_b) * rng.standard_normal((reps, n))
    p = scipy.stats.ttest_ind(a, b, axis=1, equal_var=False).pvalue
    return float(np.mean(p <= alpha))


def seeds_needed(delta: float, var_a: float, var_b: float, *, alpha: float = 0.05,
                 n_tests: int = 3, power: float = 0.8,
                 rng: np.random.Generator | None = None, reps: int = 4000) -> int:
    """GA seeds per method for the run-level test to reach ``power`` at ``delta``.

    Args:
        delta: The difference of method means to detect.
        var_a: Variance of one run's mean under the first method
            (:meth:`RunVariance.of_mean`).
        var_b: The same under the second.
        alpha: Family-wise level.
        n_tests: Pairs in the Holm family (planned at ``alpha / n_tests``).
        power: Power wanted.
        rng: With a generator, the closed-form answer is raised until Welch's test in
            :func:`simulated_power` reaches ``power`` too; None keeps the closed form.
        reps: Simulated studies per candidate number of seeds.

    Returns:
        Seeds per method (at least 2; :data:`MAX_SEEDS` when out of reach).
    """
    level = alpha / n_tests
    n = analytic_seeds(delta, var_a, var_b, level, power)
    if rng is None:
        return n
    while n < MAX_SEEDS and simulated_power(delta, var_a, var_b, n, level, rng, reps) < power:
        n += 1
    return n


def power_table(robots: pd.DataFrame, pair: tuple[str, str] = ("E+L", "R+L"), *,
                robots_per_run: Sequence[int] = (60, 100), scales: Sequence[float] = (1.0, 0.5),
                alpha: float = 0.05, n_tests: int = 3, power: float = 0.8,
                rng: np.random.Generator | None = None, value: str = "fitness"
                ) -> pd.DataFrame:
    """Seeds per method to detect the observed difference of a pair (and fractions of it).

    Args:
        robots: Robots table, fully trained robots only, with both methods of ``pair``.
        pair: The methods ``(a, b)``; the observed difference is ``mean_a − mean_b``.
        robots_per_run: Run lengths to plan for.
        scales: Multiples of the observed difference to plan for.
        alpha: Family-wise level.
        n_tests: Pairs in the Holm family.
        power: Power wanted.
        rng: See :func:`seeds_needed`.
        value: Column compared.

    Returns:
        One row per scale and run length: ``pair``, ``delta``, ``robots_per_run``,
        ``sd_run_a``, ``sd_run_b`` (run-mean standard deviations), ``effect_size``,
        ``alpha_planned``, ``seeds_closed_form`` (statsmodels) and ``seeds`` (after
        the simulation with Welch's test when ``rng`` is given).
    """
    components = variance_components(robots, value).set_index("method")
    a, b = (RunVariance(float(components.loc[m, "sd_between"]),
                        float(components.loc[m, "sd_within"])) for m in pair)
    observed = float(components.loc[pair[0], "mean"] - components.loc[pair[1], "mean"])
    rows = []
    for scale in scales:
        for m in robots_per_run:
            var_a, var_b = a.of_mean(m), b.of_mean(m)
            delta = scale * observed
            rows.append(dict(
                pair=f"{pair[0]} − {pair[1]}", delta=delta, robots_per_run=m,
                sd_run_a=math.sqrt(var_a), sd_run_b=math.sqrt(var_b),
                effect_size=abs(delta) / math.sqrt((var_a + var_b) / 2),
                alpha_planned=alpha / n_tests,
                seeds_closed_form=analytic_seeds(delta, var_a, var_b, alpha / n_tests, power),
                seeds=seeds_needed(delta, var_a, var_b, alpha=alpha, n_tests=n_tests,
                                   power=power, rng=rng)))
    return pd.DataFrame(rows)


# ---------------------------------------------------------------- CLI


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m analysis.power RUN... [--first N] [--history-only]``: print the seeds.

    Returns:
        The exit status: 0, or 2 on a bad input (one ``error:`` line on stderr).
    """
    cli = argparse.ArgumentParser(prog="python -m analysis.power",
                                  description="GA seeds per method a run-level test needs.")
    cli.add_argument("runs", nargs="+", help="run directories, or folders holding them")
    cli.add_argument("--first", type=int, default=None, help="only each run's first N robots")
    cli.add_argument("--history-only", action="store_true",
                     help="read only history.csv and summary.json (committed copies)")
    cli.add_argument("--pair", nargs=2, default=["E+L", "R+L"], metavar=("A", "B"),
                     help="the two methods whose observed difference is planned for")
    cli.add_argument("--seed", type=int, default=0, help="seed of the power simulation")
    args = cli.parse_args(argv)
    try:
        runs = (load_histories if args.history_only else load_runs)(args.runs, args.first)
        robots = fully_trained(runs.robots)
        missing = [m for m in args.pair if m not in set(robots["method"])]
        if missing:
            raise RunDirectoryError(f"{', '.join(args.runs)}: no robots of {missing}")
    except (FileNotFoundError, RunDirectoryError) as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    pair = (args.pair[0], args.pair[1])
    family = not set(pair) & set(EXTRA_METHODS)  # else a question of its own
    n_tests = len(PAIRS) if family else 1
    table = power_table(robots, pair, n_tests=n_tests, rng=np.random.default_rng(args.seed))
    first = table.iloc[0]
    level = ("alpha = 0.05 / 3 for Holm over three pairs" if family
             else "alpha = 0.05, a test of its own")
    print(f"{first['pair']} = {first['delta']:.3f}: {int(first['seeds'])} GA seeds per method "
          f"at {int(first['robots_per_run'])} robots per run (80 % power, Welch on run means, "
          f"{level})")
    print(markdown_table(table), end="")
    return 0


if __name__ == "__main__":
    sys.exit(main())
