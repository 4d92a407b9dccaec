"""The genetic algorithm's parts (paper section 6), each a dataclass a config names with
``_target_`` (``conf/ga/``, built by :func:`evo.config.typed`).

* ``Roulette``: fitness-proportional selection (paper Eq. 9). Fitness may be negative, so
  probabilities use fitness shifted by the population minimum plus ``epsilon``
  (SPEC decision): ``p_i = (f_i - min f + eps) / sum_j (f_j - min f + eps)``. The worst
  member keeps a small chance ``eps / sum``; with all-equal fitness selection is uniform.
* ``ReplaceWorst``: steady-state replacement: the offspring replaces the worst member
  only if it is strictly fitter.
* ``BudgetSchedule``: training budget per evaluation: ``initial`` env steps for the
  initial robots, then rising linearly from ``first`` for the first offspring to
  ``last`` for the last one (paper section 7: 50k -> 250k); an offspring that starts
  from a parent's policy (``ga.inheritance``) gets ``inherited`` times that.
* ``Evolve`` (structure strategy ``E``): two parents by selection, one offspring by
  subtree crossover (optionally mutated). ``RandomStructures`` (``R``): every new robot is
  a fresh random structure, no parents. ``ga.structure`` chooses one by naming its
  :class:`StructureChoice` (``EvolveChoice``, ``RandomChoice``).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np
import numpy.typing as npt

from evo.checks import SWAPPABLE, at_least, positive, within
from evo.components.inheritance import INHERITANCE_MODES
from evo.early_rejection import EarlyRejection
from evo.robot.operators import (
    MUTATIONS,
    GeneratorParams,
    Mutation,
    OperatorError,
    Origins,
    crossover,
    mutate,
    random_robot,
    surviving_origins,
)
from evo.robot.tree import Robot
from evo.robot.validate import Limits
from evo.run.records import Member

# ---- selection ------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class Roulette:
    """Roulette-wheel selection on fitness shifted by the minimum plus ``epsilon``.

    Attributes:
        epsilon: Added to every shifted fitness so the worst member can still be picked
            and all-equal fitness gives uniform selection (fitness units).
        distinct: Draw the two parents without replacement.
    """

    epsilon: float = 0.01
    distinct: bool = True

    def __post_init__(self) -> None:
        positive(self, "epsilon")

    def probabilities(self, fitness: npt.ArrayLike) -> npt.NDArray[np.float64]:
        """Selection probability of every member (paper Eq. 9 on shifted fitness)."""
        f = np.asarray(fitness, dtype=np.float64)
        if f.size == 0 or not np.isfinite(f).all():
            raise ValueError(f"selection needs finite fitness values, got {f.tolist()}")
        shifted = f - f.min() + self.epsilon
        probabilities: npt.NDArray[np.float64] = shifted / shifted.sum()
        return probabilities

    def select(self, fitness: npt.ArrayLike, rng: np.random.Generator, k: int = 2) -> list[int]:
        """Indices of ``k`` parents."""
        p = self.probabilities(fitness)
        replace = not self.distinct or len(p) < k
        return [int(i) for i in rng.choice(len(p), size=k, replace=replace, p=p)]


# ---- replacement ----------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class ReplaceWorst:
    """Steady-state replacement: the offspring replaces the worst member if fitter."""

    def apply(self, population: list[Member], offspring: Member) -> Member | None:
        """Replace in place; returns the member that left, or None when rejected."""
        if not math.isfinite(offspring.fitness) or not population:
            return None
        worst = min(range(len(population)), key=lambda i: population[i].fitness)
        if offspring.fitness > population[worst].fitness:
            gone = population[worst]
            population[worst] = offspring
            return gone
        return None


# ---- budget schedule ------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class BudgetSchedule:
    """Env steps of training per evaluation.

    Attributes:
        initial: Budget of every robot of the initial population, env steps.
        first: Budget of the first offspring, env steps.
        last: Budget of the last offspring, env steps (linear in between).
        inherited: The share of its scheduled budget an offspring gets when it starts
            from a parent's policy (``ga.inheritance``; 1 = the same budget).
    """

    initial: int = 50_000
    first: int = 50_000
    last: int = 250_000
    inherited: float = 1.0

    def __post_init__(self) -> None:
        at_least(self, 1, "initial", "first", "last", note=" env step")
        within(self, 1e-3, 1.0, "inherited", note=" (a share of the scheduled budget)")
        if self.last < self.first:
            raise ValueError(f"last ({self.last}) must be >= first ({self.first}): budgets "
                             "rise (or stay) over the offspring, as in the paper")

    def budget(self, birth: int, population_size: int, robot_budget: int) -> int:
        """Budget of the robot born ``birth``-th (0-based) in a run of ``robot_budget``."""
        if birth < population_size:
            return self.initial
        offspring = robot_budget - population_size
        if offspring <= 1:
            return self.last
        frac = (birth - population_size) / (offspring - 1)
        return round(self.first + (self.last - self.first) * min(frac, 1.0))

    def inherited_budget(self, budget: int) -> int:
        """The budget of an offspring scheduled ``budget`` env steps that inherits."""
        return max(1, round(budget * self.inherited))


# ---- structure strategies -------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class Offspring:
    """A new robot and where it came from.

    Attributes:
        robot: The new robot.
        parents: The parents' names (none for a random robot).
        operator: How it was made.
        origins: Which module of which parent (an index of ``parents``) each of its
            modules came from (``evo.robot.operators.Origins``; empty for a random robot).
    """

    robot: Robot
    parents: tuple[str, ...] = ()
    operator: str = "random"
    origins: Origins = field(default_factory=dict)


class StructureStrategy(Protocol):
    """Makes the next robot to evaluate from the population as it stands."""

    @property
    def code(self) -> str:
        """``E`` or ``R``: the strategy's letter in the method name."""

    def initial(self, rng: np.random.Generator) -> Offspring: ...

    def breed(self, population: Sequence[Member], rng: np.random.Generator) -> Offspring: ...


@dataclass(frozen=True, slots=True)
class RandomStructures:
    """Structure strategy ``R``: every robot is a fresh random structure."""

    generator: GeneratorParams = field(default_factory=GeneratorParams)
    limits: Limits = field(default_factory=Limits)
    code: str = "R"

    def initial(self, rng: np.random.Generator) -> Offspring:
        return Offspring(random_robot(rng, self.generator, self.limits))

    def breed(self, population: Sequence[Member], rng: np.random.Generator) -> Offspring:
        return self.initial(rng)


@dataclass(frozen=True, slots=True)
class Evolve:
    """Structure strategy ``E``: crossover of two selected parents (paper section 6).

    Its settings are the ``ga`` group's own (``selection``, ``crossover_tries``,
    ``parent_tries``, ``mutation_rate``, ``mutation_operators``), read from ``ga``. The
    initial population is random, from ``fresh``, whose generator and limits also
    govern mutation.

    Attributes:
        ga: The GA config whose breeding settings apply.
        fresh: Where the initial robots come from.
    """

    ga: GAConfig
    fresh: RandomStructures = field(default_factory=RandomStructures)
    code: str = "E"

    def initial(self, rng: np.random.Generator) -> Offspring:
        return self.fresh.initial(rng)

    def breed(self, population: Sequence[Member], rng: np.random.Generator) -> Offspring:
        ga, limits = self.ga, self.fresh.limits
        fitness = [m.fitness for m in population]
        for _ in range(ga.parent_tries):
            i, j = ga.selection.select(fitness, rng)
            a, b = population[i], population[j]
            try:
                result = crossover(a.robot, b.robot, rng, limits, ga.crossover_tries)
            except OperatorError:
                continue
            # A swap of identical subtrees gives a parent back: not a new robot.
            novel = [c for c in result.offspring if c not in (a.robot, b.robot)]
            if not novel:
                continue
            child = novel[int(rng.integers(len(novel)))]
            origins = result.origins[result.offspring.index(child)]
            operator = "crossover"
            if ga.mutation_rate and rng.random() < ga.mutation_rate:
                crossed = child
                child = mutate(child, rng, ga.mutation_operators, self.fresh.generator, limits)
                origins = surviving_origins(crossed, child, origins)
                operator = "crossover+mutation"
            return Offspring(child, (a.name, b.name), operator, origins)
        raise OperatorError(f"no valid offspring from {ga.parent_tries} parent pairs")


# ---- the ga config group ----------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class StructureChoice:
    """What ``ga.structure`` names with its ``_target_``: the strategy that makes the run's
    robots (``conf/ga/structure/``). A new strategy is a subclass whose :meth:`strategy`
    makes it; ``ga.structure=E|R`` are :data:`evo.config.STRUCTURE_LETTERS`."""

    def strategy(self, ga: GAConfig, fresh: RandomStructures) -> StructureStrategy:
        """The strategy, with the ``ga`` config's breeding settings and ``fresh``, the
        random structures of the ``morphology`` group."""
        raise NotImplementedError(f"{type(self).__name__} makes no structure strategy")


@dataclass(frozen=True, slots=True)
class EvolveChoice(StructureChoice):
    """``E``, the paper's method: offspring by crossover of two parents (:class:`Evolve`)."""

    def strategy(self, ga: GAConfig, fresh: RandomStructures) -> StructureStrategy:
        return Evolve(ga, fresh)


@dataclass(frozen=True, slots=True)
class RandomChoice(StructureChoice):
    """``R``, the ablation's baseline: every robot a fresh random one
    (:class:`RandomStructures`)."""

    def strategy(self, ga: GAConfig, fresh: RandomStructures) -> StructureStrategy:
        return fresh


@dataclass(frozen=True, slots=True)
class GAConfig:
    """The ``ga`` config group (``conf/ga/steady_state.yaml``), whole.

    Attributes:
        population_size: Robots in the population (the initial ones are random).
        robot_budget: Robots evaluated in all, initial ones included.
        structure: Which structure strategy makes the robots.
        selection: How parents are chosen (``E``).
        replacement: Steady-state replacement.
        schedule: Training budget of every evaluation, env steps.
        crossover_tries: Swaps tried per parent pair before a new pair is drawn (``E``).
        parent_tries: Parent pairs tried before breeding gives up (``E``).
        mutation_rate: Probability an offspring is also mutated (``E``; 0 in the paper).
        mutation_operators: The mutation operators an offspring may get, one drawn
            at random (``E``).
        eval_timeout_s: Wall-clock limit of one evaluation, seconds, checked after
            every collector batch (0 = none).
        inheritance: Whether an offspring's policy starts from a parent's, a key of
            :data:`evo.components.inheritance.INHERITANCE_MODES` (``off``: from scratch,
            as in the paper; ``parent``: its parent's with the most motors and pivots).
            Quote ``"off"`` in YAML, which reads a bare off as false.
        early_rejection: When an offspring's training may stop early.
    """

    population_size: int = 20
    robot_budget: int = 100
    structure: StructureChoice = field(default_factory=EvolveChoice, metadata=SWAPPABLE)
    selection: Roulette = field(default_factory=Roulette, metadata=SWAPPABLE)
    replacement: ReplaceWorst = field(default_factory=ReplaceWorst, metadata=SWAPPABLE)
    schedule: BudgetSchedule = field(default_factory=BudgetSchedule, metadata=SWAPPABLE)
    crossover_tries: int = 100
    parent_tries: int = 20
    mutation_rate: float = 0.0
    mutation_operators: tuple[Mutation, ...] = field(
        default=tuple(MUTATIONS.values()), metadata=SWAPPABLE)
    eval_timeout_s: float = 0  # 0, as run directories' config.yaml have always said
    inheritance: str = "off"
    early_rejection: EarlyRejection = field(default_factory=EarlyRejection)

    def __post_init__(self) -> None:
        at_least(self, 2, "population_size")
        if self.robot_budget < self.population_size:
            raise ValueError(
                f"robot_budget ({self.robot_budget}) must be >= population_size "
                f"({self.population_size})"
            )
        at_least(self, 1, "crossover_tries", "parent_tries")
        at_least(self, 0, "eval_timeout_s", note=" (0 = none)")
        if not 0 <= self.mutation_rate <= 1:
            raise ValueError(f"mutation_rate must be in [0, 1], got {self.mutation_rate}")
        if self.inheritance not in INHERITANCE_MODES:
            raise ValueError(f"inheritance: expected one of {', '.join(INHERITANCE_MODES)}, "
                             f"got {self.inheritance!r}")

    def strategy(self, generator: GeneratorParams | None = None,
                 limits: Limits | None = None) -> StructureStrategy:
        """The structure strategy ``structure`` names, making robots with ``generator``
        within ``limits`` (the ``morphology`` group; defaults when None)."""
        fresh = RandomStructures(generator or GeneratorParams(), limits or Limits())
        return self.structure.strategy(self, fresh)

    def expected_budgets(self) -> list[int]:
        """:meth:`budgets` as the run is expected to spend them: with ``inheritance`` on,
        an offspring's is its inherited share (a random fallback, which has no parent,
        trains for the whole; the progress bar's estimate and the start-up checks need
        no more)."""
        budgets = self.budgets()
        if self.inheritance == "off":
            return budgets
        return budgets[:self.population_size] + [
            self.schedule.inherited_budget(b) for b in budgets[self.population_size:]]

    def budgets(self) -> list[int]:
        """The training budget of every robot of the run, in birth order."""
        return [self.schedule.budget(b, self.population_size, self.robot_budget)
                for b in range(self.robot_budget)]
