"""The GA's parts (``evo/components``): selection, replacement, budget schedule, the two
structure strategies, and the executors.

Frequencies are checked with a chi-square test on seeded draws, so every test is
deterministic; each such test also shows that the same draws reject a wrong
distribution, so it can fail.
"""

from __future__ import annotations

import dataclasses
import itertools
import json
import math
import os
from collections import Counter
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from scipy.stats import chisquare

from evo.components.executors import EvaluationLost, LocalExecutor, RayExecutor, SerialExecutor
from evo.components.ga import (
    BudgetSchedule,
    Evolve,
    GAConfig,
    RandomStructures,
    ReplaceWorst,
    Roulette,
)
from evo.envs.params import EnvConfig
from evo.evaluation import Job, Outcome, evaluate
from evo.learners.ppo import PPO
from evo.record.readback import read_curve
from evo.robot import GeneratorParams, Limits, Robot, parse_robot, random_robot
from evo.robot.builder import PhysicsParams
from evo.run.records import Candidate, Member

DRAWS = 10_000
ALPHA = 1e-3  # a seeded test: the threshold only has to separate right from wrong

FITNESS_CASES = {
    "mixed": [0.5, -0.2, 1.7, 0.0, -1.0],
    "all-negative": [-0.9, -0.4, -1.0, -0.95, -0.1],
    "all-equal": [-0.3, -0.3, -0.3, -0.3, -0.3],
    "one-outlier": [2.5, -1.0, -1.0, -0.99, -0.98],
}


def eq9_shifted(fitness: Sequence[float], eps: float) -> np.ndarray:
    """Paper Eq. 9 on fitness shifted by the population minimum plus ``eps``."""
    f = np.asarray(fitness, dtype=float)
    shifted = f - f.min() + eps
    return shifted / shifted.sum()


def pair_probabilities(p: np.ndarray, distinct: bool) -> dict[tuple[int, int], float]:
    """Probability of every ordered parent pair drawn from ``p``."""
    n = len(p)
    if not distinct:
        return {(i, j): p[i] * p[j] for i in range(n) for j in range(n)}
    return {(i, j): p[i] * p[j] / (1 - p[i]) for i in range(n) for j in range(n) if i != j}


def chi2_pvalue(observed: Counter[Any], expected: dict[Any, float], draws: int) -> float:
    assert set(observed) <= set(expected), f"impossible outcomes {set(observed) - set(expected)}"
    keys = sorted(expected)
    obs = np.array([observed.get(k, 0) for k in keys], dtype=float)
    exp = np.array([expected[k] * draws for k in keys])
    return float(chisquare(obs, exp).pvalue)


# ---- roulette selection ---------------------------------------------------------------------


@pytest.mark.parametrize("case", FITNESS_CASES)
def test_roulette_probabilities_are_eq9_on_shifted_fitness(case: str) -> None:
    fitness = FITNESS_CASES[case]
    roulette = Roulette(epsilon=0.05)
    p = roulette.probabilities(fitness)
    np.testing.assert_allclose(p, eq9_shifted(fitness, 0.05), rtol=1e-12)
    assert p.sum() == pytest.approx(1.0)
    assert (p > 0).all(), "the worst member keeps a chance"
    # Fitness order is probability order (monotone), whatever the sign.
    for i, j in itertools.permutations(range(len(fitness)), 2):
        if fitness[i] > fitness[j]:
            assert p[i] > p[j], (case, i, j, p)
        if fitness[i] == fitness[j]:
            assert p[i] == pytest.approx(p[j])


@pytest.mark.parametrize("case", FITNESS_CASES)
def test_roulette_single_draws_follow_eq9(case: str) -> None:
    fitness = FITNESS_CASES[case]
    roulette = Roulette(epsilon=0.05)
    rng = np.random.default_rng(1234)
    counts = Counter(roulette.select(fitness, rng, k=1)[0] for _ in range(DRAWS))
    expected = eq9_shifted(fitness, 0.05)
    pvalue = chi2_pvalue(counts, dict(enumerate(expected)), DRAWS)
    assert pvalue > ALPHA, f"{case}: counts {sorted(counts.items())}, expected {expected}"
    # The same draws reject selection that ignores fitness (uniform), unless it is uniform.
    uniform = np.full(len(fitness), 1 / len(fitness))
    if not np.allclose(expected, uniform):
        assert chi2_pvalue(counts, dict(enumerate(uniform)), DRAWS) < 1e-9


@pytest.mark.parametrize("distinct", [True, False])
@pytest.mark.parametrize("case", FITNESS_CASES)
def test_roulette_parent_pairs_follow_eq9(case: str, distinct: bool) -> None:
    # Two parents per breeding step: the first by Eq. 9, the second by Eq. 9 among the
    # others (distinct) or among all (with replacement).
    fitness = FITNESS_CASES[case]
    roulette = Roulette(epsilon=0.05, distinct=distinct)
    rng = np.random.default_rng(99)
    pairs = Counter(tuple(roulette.select(fitness, rng)) for _ in range(DRAWS))
    p = eq9_shifted(fitness, 0.05)
    expected = pair_probabilities(p, distinct)
    if distinct:
        assert all(i != j for i, j in pairs), "a distinct pair repeated a member"
    pvalue = chi2_pvalue(pairs, expected, DRAWS)
    assert pvalue > ALPHA, f"{case}: pair frequencies differ from Eq. 9 (p={pvalue:.2g})"
    if not distinct:
        assert sum(pairs[(i, i)] for i in range(len(p))) > 0.05 * DRAWS
    elif not np.allclose(p, p[0]):
        # The same draws reject independent draws that merely skip repeats.
        independent = pair_probabilities(p, distinct=False)
        norm = 1 - sum(independent[(i, i)] for i in range(len(p)))
        wrong = {k: independent[k] / norm for k in expected}
        assert chi2_pvalue(pairs, wrong, DRAWS) < 1e-9


def test_roulette_with_fewer_members_than_parents_repeats_one() -> None:
    assert Roulette().select([0.3], np.random.default_rng(0)) == [0, 0]


@pytest.mark.parametrize("bad", [[], [0.1, float("nan")], [float("inf"), 0.0]])
def test_roulette_rejects_missing_or_non_finite_fitness(bad: list[float]) -> None:
    with pytest.raises(ValueError, match="finite fitness"):
        Roulette().probabilities(bad)


def test_roulette_needs_a_positive_epsilon() -> None:
    with pytest.raises(ValueError, match="epsilon must be positive"):
        Roulette(epsilon=0.0)


# ---- replacement --------------------------------------------------------------------------


def member(name: str, fitness: float) -> Member:
    return Member(name, ROBOT, fitness)


def test_replace_worst_only_when_the_offspring_beats_the_minimum() -> None:
    population = [member("a", 0.2), member("b", -0.5), member("c", 1.0)]
    assert ReplaceWorst().apply(population, member("x", -0.5)) is None, "a tie is no win"
    assert ReplaceWorst().apply(population, member("y", -0.7)) is None
    assert ReplaceWorst().apply(population, member("z", float("nan"))) is None
    assert [m.name for m in population] == ["a", "b", "c"]
    gone = ReplaceWorst().apply(population, member("w", -0.4999))
    assert gone is not None and gone.name == "b"
    assert [m.name for m in population] == ["a", "w", "c"]


def test_replace_worst_keeps_the_population_size_over_a_long_run() -> None:
    rng = np.random.default_rng(5)
    population = [member(f"m{i}", float(f)) for i, f in enumerate(rng.normal(size=20))]
    accepted = 0
    for step in range(500):
        before = [m.fitness for m in population]
        new = member(f"o{step}", float(rng.normal(0.5, 1.0)))
        gone = ReplaceWorst().apply(population, new)
        assert len(population) == 20
        after = [m.fitness for m in population]
        if new.fitness > min(before):
            accepted += 1
            assert gone is not None and gone.fitness == min(before)
            assert sorted(after) == sorted([*_minus_one(before), new.fitness])
        else:
            assert gone is None and after == before
        assert min(after) >= min(before), "the minimum never falls"
    assert 0 < accepted < 500


def _minus_one(values: list[float]) -> list[float]:
    rest = list(values)
    rest.remove(min(rest))
    return rest


# ---- budget schedule ----------------------------------------------------------------------


def test_budget_schedule_is_50k_then_linear_to_250k_at_the_last_offspring() -> None:
    schedule = BudgetSchedule()  # the paper's numbers are the defaults
    budgets = [schedule.budget(b, 20, 100) for b in range(100)]
    assert budgets[:20] == [50_000] * 20
    assert budgets[20] == 50_000 and budgets[99] == 250_000
    step = (250_000 - 50_000) / 79
    for birth in range(20, 100):
        assert abs(budgets[birth] - (50_000 + step * (birth - 20))) <= 0.5, birth
    diffs = np.diff(budgets[20:])
    assert diffs.min() >= math.floor(step) and diffs.max() <= math.ceil(step)


def test_budget_schedule_edges() -> None:
    schedule = BudgetSchedule(initial=1000, first=2000, last=3000)
    assert schedule.budget(4, 4, 5) == 3000, "a single offspring gets the last budget"
    assert schedule.budget(4, 4, 4) == 3000
    assert schedule.budget(12, 4, 10) == 3000, "births past the budget stay at the last"
    for key in ("initial", "first", "last"):
        with pytest.raises(ValueError, match=f"{key} must be >= 1"):
            BudgetSchedule(**{key: 0})


# ---- structure strategies -----------------------------------------------------------------

GENERATOR = GeneratorParams()
LIMITS = Limits()
FRESH = RandomStructures(GENERATOR, LIMITS)
ROBOT = random_robot(np.random.default_rng(0), GENERATOR, LIMITS)


class Untouchable(Sequence[Member]):
    """A population that fails the test when anything looks at it."""

    def __getitem__(self, index: Any) -> Any:
        raise AssertionError("the R strategy read the population")

    def __len__(self) -> int:
        raise AssertionError("the R strategy read the population")

    def __iter__(self) -> Iterator[Member]:
        raise AssertionError("the R strategy read the population")


def test_random_structures_never_use_parents() -> None:
    strategy = RandomStructures(GENERATOR, LIMITS)
    assert strategy.code == "R"
    rng, same = np.random.default_rng(7), np.random.default_rng(7)
    for _ in range(30):
        offspring = strategy.breed(Untouchable(), rng)
        assert offspring.parents == () and offspring.operator == "random"
        # The new robot is what a fresh random draw gives: nothing of the population.
        assert offspring.robot == random_robot(same, GENERATOR, LIMITS)


def robot_doc(robot: Robot) -> dict[str, Any]:
    doc: dict[str, Any] = json.loads(robot.canonical_json())
    return doc


def swappable(root: dict[str, Any]) -> Iterator[tuple[tuple[int, ...], str, dict[str, Any]]]:
    """(path, parent type, edge) of every non-root, non-wheel node."""
    stack: list[tuple[tuple[int, ...], dict[str, Any]]] = [((), root)]
    while stack:
        path, node = stack.pop()
        for edge in node.get("children", []):
            if edge["module"]["type"] != "wheel":
                yield (*path, edge["face"]), node["type"], edge
                stack.append(((*path, edge["face"]), edge["module"]))


def graft(root: dict[str, Any], path: tuple[int, ...], donor: dict[str, Any]) -> dict[str, Any]:
    """``root`` with the subtree at ``path`` replaced by ``donor``'s (its face stays)."""
    node = {**root, "children": [dict(e) for e in root.get("children", [])]}
    for edge in node["children"]:
        if edge["face"] == path[0]:
            if len(path) == 1:
                edge["rotation"], edge["module"] = donor["rotation"], donor["module"]
            else:
                edge["module"] = graft(edge["module"], path[1:], donor)
    return node


def one_swap_children(a: Robot, b: Robot) -> set[Robot]:
    """Every robot made of ``a`` with one subtree replaced by a subtree of ``b``."""
    out = set()
    ra, rb = robot_doc(a)["root"], robot_doc(b)["root"]
    for path, parent_type, _ in swappable(ra):
        for _, donor_parent_type, donor in swappable(rb):
            if parent_type == donor_parent_type:
                doc = {"format": "evo.robot/1", "root": graft(ra, path, donor)}
                try:
                    out.add(parse_robot(doc, limits=LIMITS))
                except ValueError:
                    continue  # an invalid swap is never an offspring
    return out


def population_of(seed: int, size: int = 6) -> list[Member]:
    rng = np.random.default_rng(seed)
    robots = [random_robot(rng, GENERATOR, LIMITS) for _ in range(size)]
    return [Member(f"m{i}", r, float(rng.normal())) for i, r in enumerate(robots)]


@pytest.mark.parametrize("seed", range(12))
def test_evolve_offspring_is_a_parent_with_one_subtree_of_the_other(seed: int) -> None:
    population = population_of(seed)
    strategy = Evolve(GAConfig(), FRESH)
    offspring = strategy.breed(population, np.random.default_rng(seed))
    assert offspring.operator == "crossover" and len(offspring.parents) == 2
    by_name = {m.name: m.robot for m in population}
    a, b = (by_name[n] for n in offspring.parents)
    assert offspring.robot not in (a, b), "a crossover that gives a parent back is no offspring"
    children = one_swap_children(a, b) | one_swap_children(b, a)
    assert offspring.robot in children, (
        f"{offspring.robot.canonical_json()} is not {offspring.parents[0]} or "
        f"{offspring.parents[1]} with one subtree swapped in"
    )


class Fixed:
    """A selection that always returns the same indices."""

    def __init__(self, *indices: int) -> None:
        self.indices = list(indices)
        self.calls = 0

    def select(self, fitness: Any, rng: np.random.Generator, k: int = 2) -> list[int]:
        self.calls += 1
        return self.indices


def test_evolve_breeds_from_the_selected_parents() -> None:
    population = population_of(3)
    for i, j in [(0, 4), (5, 2), (1, 3)]:
        selection = Fixed(i, j)
        ga = GAConfig(selection=selection)  # type: ignore[arg-type]
        strategy = Evolve(ga, FRESH)
        offspring = strategy.breed(population, np.random.default_rng(i * 10 + j))
        assert offspring.parents == (f"m{i}", f"m{j}")
        a, b = population[i].robot, population[j].robot
        assert offspring.robot in one_swap_children(a, b) | one_swap_children(b, a)


def test_evolve_uses_roulette_on_the_population_fitness() -> None:
    # Parent names over many breeding steps follow the pair law of Eq. 9.
    population = population_of(11, size=4)
    fitness = [m.fitness for m in population]
    strategy = Evolve(GAConfig(), FRESH)
    rng = np.random.default_rng(0)
    index = {m.name: i for i, m in enumerate(population)}
    pairs = Counter(
        tuple(index[n] for n in strategy.breed(population, rng).parents) for _ in range(1500)
    )
    expected = pair_probabilities(eq9_shifted(fitness, 0.01), distinct=True)
    # Breeding redraws a pair when crossover fails, so only test when it rarely does:
    # every pair of these parents has a crossover site.
    assert chi2_pvalue(pairs, expected, 1500) > ALPHA, (sorted(pairs.items()), expected)


def test_evolve_gives_up_with_a_clear_error_on_parents_without_crossover_sites() -> None:
    from evo.robot import OperatorError

    motor_only = parse_robot(
        {
            "format": "evo.robot/1",
            "root": {
                "type": "brain",
                "children": [
                    {
                        "face": 0,
                        "module": {
                            "type": "motor",
                            "children": [
                                {"face": 2, "module": {"type": "wheel"}},
                                {"face": 3, "module": {"type": "wheel"}},
                            ],
                        },
                    }
                ],
            },
        }
    )
    population = [Member("a", motor_only, 0.0), Member("b", motor_only, 1.0)]
    with pytest.raises(OperatorError, match="no valid offspring from 3 parent pairs"):
        Evolve(GAConfig(parent_tries=3), FRESH).breed(
            population, np.random.default_rng(0)
        )


# ---- executors --------------------------------------------------------------------------


def square(x: int) -> int:
    return x * x


def fail(x: int) -> int:
    raise RuntimeError(f"bad input {x}")


def test_serial_executor_returns_results_and_errors_through_futures() -> None:
    executor = SerialExecutor()
    assert executor.submit(square, 7).result() == 49
    future = executor.submit(fail, 3)
    with pytest.raises(RuntimeError, match="bad input 3"):
        future.result()


TINY = PPO(num_envs=4, rollout_steps=32, epochs=1, minibatch_size=64, hidden=(16,))


def tiny_job(run_dir: Path) -> Job:
    return Job(PhysicsParams(), EnvConfig(), TINY, str(run_dir))


def tiny_candidates() -> list[Candidate]:
    """One robot, trained for a single collector batch."""
    robot = random_robot(np.random.default_rng(4), GENERATOR, LIMITS)
    return [Candidate(0, robot.name, robot.canonical_json(), 128, 1000)]


BROKEN = Candidate(0, "broken", json.dumps({"format": "evo.robot/1", "root": {"type": "motor"}}),
                   256, 1)


def test_an_evaluation_past_its_time_limit_is_an_error_outcome(tmp_path: Path) -> None:
    (candidate,) = tiny_candidates()
    job = dataclasses.replace(tiny_job(tmp_path), timeout_s=1e-6)
    outcome = evaluate(dataclasses.replace(candidate, budget=10 * 128), job)
    assert outcome.error and outcome.error.startswith("EvaluationTimeout: "), outcome.error
    assert "timed out after" in outcome.error and "ga.eval_timeout_s" in outcome.error
    assert "\n" not in outcome.error, "an expected outcome is one line, with no traceback"
    assert not (tmp_path / "evals" / f"{candidate.name}.log").exists()
    assert math.isnan(outcome.fitness)
    # Stopped after its first batch, and the recording of that batch was kept.
    curve = read_curve(tmp_path / "evals" / f"{candidate.name}.mcap")
    assert curve["env_steps"].tolist() == [128.0]


def test_an_unsimulatable_robot_is_an_error_outcome(tmp_path: Path) -> None:
    outcome = evaluate(BROKEN, tiny_job(tmp_path))
    assert outcome.error and "broken" in outcome.error and "\n" not in outcome.error
    assert outcome.error.endswith("(traceback in evals/broken.log)"), outcome.error
    assert math.isnan(outcome.fitness) and outcome.env_steps == 0
    assert not (tmp_path / "evals" / "broken.pt").exists()


@pytest.fixture(scope="module")
def serial_outcomes(tmp_path_factory: pytest.TempPathFactory) -> list[Outcome]:
    run_dir = tmp_path_factory.mktemp("serial")
    executor = SerialExecutor()
    return [executor.submit(evaluate, t, tiny_job(run_dir)).result() for t in tiny_candidates()]


def same_results(a: list[Outcome], b: list[Outcome]) -> None:
    for x, y in zip(a, b, strict=True):
        assert x.error is None and y.error is None, (x.error, y.error)
        assert (x.name, x.env_steps, x.episodes) == (y.name, y.env_steps, y.episodes)
        assert x.fitness == y.fitness, f"{x.name}: {x.fitness} != {y.fitness}"


@pytest.mark.slow
def test_local_executor_gives_the_serial_fitness_and_survives_a_dead_worker(
    serial_outcomes: list[Outcome], tmp_path: Path
) -> None:
    executor = LocalExecutor(workers=1, retries=0)
    try:
        futures = [executor.submit(evaluate, t, tiny_job(tmp_path)) for t in tiny_candidates()]
        same_results(serial_outcomes, [f.result(timeout=120) for f in futures])
        pid = executor.submit(os.getpid).result(timeout=60)
        # A worker dies (no retries here): its task is lost, and a fresh pool (one, not
        # two beside each other oversubscribing the cores) runs what comes next, also
        # after a late report of the same death.
        with pytest.raises(EvaluationLost, match="exit code 3"):
            executor.submit(os._exit, 3).result(timeout=60)
        before = [executor.submit(os.getpid) for _ in range(3)]
        executor.restart()  # a late report of the same death
        after = [executor.submit(os.getpid) for _ in range(3)]
        pids = {f.result(timeout=60) for f in before + after}
        assert len(pids) == 1 and pid not in pids, f"{len(pids)} new workers for workers=1"
    finally:
        executor.shutdown()
    assert all(math.isfinite(o.fitness) for o in serial_outcomes)
    for candidate in tiny_candidates():
        assert (tmp_path / "evals" / f"{candidate.name}.pt").is_file()


@pytest.mark.slow
@pytest.mark.long  # Ray starts in the README's soak command
def test_ray_executor_gives_the_serial_fitness(
    serial_outcomes: list[Outcome], tmp_path: Path
) -> None:
    ray = pytest.importorskip("ray", reason="the ray extra is not installed")
    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False)
    try:
        executor = RayExecutor()
        assert executor.workers == 2, "one evaluation per CPU of the local instance"
        futures = [executor.submit(evaluate, t, tiny_job(tmp_path)) for t in tiny_candidates()]
        same_results(serial_outcomes, [f.result(timeout=600) for f in futures])  # slow when busy
        # A failing evaluation comes back as an error outcome, any other error raises.
        outcome = executor.submit(evaluate, BROKEN, tiny_job(tmp_path)).result(timeout=60)
        assert outcome.error and math.isnan(outcome.fitness)
        with pytest.raises(ValueError, match="Expecting"):
            executor.submit(json.loads, "{").result(timeout=60)
        # Early rejection through Ray: the minimum to beat travels with the candidate,
        # and the worker stops where the serial evaluation stops.
        from test_early_rejection import NEAR, RULE, TINY_LEARNER, real_candidate

        early = Job(PhysicsParams(), NEAR, TINY_LEARNER, str(tmp_path / "early"), early=RULE)
        stopped = executor.submit(evaluate, real_candidate(5.0), early).result(timeout=600)
        assert stopped.error is None and stopped.stopped_early and stopped.env_steps == 512
        kept = executor.submit(evaluate, real_candidate(-10.0), early).result(timeout=600)
        assert not kept.stopped_early and kept.env_steps >= 2560
    finally:
        ray.shutdown()
