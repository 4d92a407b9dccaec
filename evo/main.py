"""evo's entry point: ``python evo/main.py +exp=<name> [key=value ...]``.

This is the config edge (STYLE rule 1): the Hydra config is turned into typed objects
here and nothing below sees a ``DictConfig``. Outputs go only to the run directory
(Hydra's output dir, chosen with ``hydra.run.dir=...``).

Tasks (``task=``):

* ``evolve`` (the default): the GA of ``conf/ga``, evaluations on ``conf/executor``;
  ``resume=<run dir>`` continues a stopped run in its own directory, to another robot
  budget with ``ga.robot_budget=N`` (:func:`with_robot_budget`);
* ``robots``: generate, save and picture random robots;
* ``train``: train one robot (``robot=FILE``) and evaluate it deterministically;
* ``evaluate``: run a trained policy (``robot=FILE checkpoint=FILE``);
* ``retrain``: train fixed structures under independent seeds and report their noise
  ceiling (``+exp=retrain``, ``evo.retrain``); ``resume=<run dir>`` continues it;
* ``noise_sweep``: one trial of the noise-ceiling sweep (``+exp=noise_sweep``); it
  returns the trial's objectives to Hydra's Optuna sweeper.

What the config does not choose, the code of ``task=evolve`` (the run's store, the
evaluation, the run's log), is an argument of :func:`cli`: a script that runs evo with
its own (a store that fails at a chosen write, in the fault tests) passes an
:class:`EvolveCode`; ``python evo/main.py`` runs with evo's own.
"""

from __future__ import annotations

import copy
import functools
import logging
import os
import sys
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path

import hydra
import numpy as np
import torch
from hydra.core.hydra_config import HydraConfig
from omegaconf import DictConfig, OmegaConf

from evo.components.executors import EvalExecutor
from evo.components.ga import GAConfig, StructureStrategy
from evo.config import (
    CONF_DIR,
    ConfigError,
    current,
    method_label,
    older_overrides,
    structure_letter,
    typed,
)
from evo.edge import EvoConfig, retraining, typed_config, warn_if_failures_cannot_end
from evo.evaluation import Job, Outcome, evaluate
from evo.evolution import Evolution, RunLog
from evo.fidelity import agreement, ceiling_line
from evo.interrupt import Interrupted, critical, handle_signals
from evo.learners.common import SavePolicy
from evo.pool import EvaluationPool
from evo.record import OpenRecorder, RecordConfig
from evo.record.run import RunMetadata
from evo.retrain import RetrainConfig, RetrainError, run_trainings
from evo.robot import (
    InvalidRobotError,
    Robot,
    RobotFileError,
    load_robot,
    random_robots,
)
from evo.run.files import (
    RunDirectoryBusy,
    RunLock,
    busy_message,
    is_locked,
    write_failure,
    write_text,
)
from evo.run.layout import RetrainLayout, RunLayout
from evo.run.records import Candidate, HistoryRow, read_retrain_settings
from evo.run.store import RunStore, SavedState
from evo.schemas import register_schemas
from evo.sweep import trial_overrides

register_schemas()  # the defaults conf/ starts from, before Hydra composes (evo.schemas)


@dataclass(frozen=True)
class Run:
    """What a task is given: the typed config it runs with and its run directory.

    Attributes:
        config: The config, typed once (:func:`evo.edge.typed_config`): the command's,
            or with ``resume=DIR`` the one DIR was started with.
        out: The run directory.
        lock: Its lock, held by this process.
        resuming: Whether ``resume=DIR`` continues the run in ``out``.
        started_ga: With ``resume=DIR ga.robot_budget=N``, the ``ga`` group the run was
            started with (``config.ga`` has the new budget; :func:`check_robot_budget`).
    """

    config: EvoConfig
    out: Path
    lock: RunLock
    resuming: bool = False
    started_ga: GAConfig | None = None


def _robot(config: EvoConfig) -> Robot:
    """The robot named by ``robot=``; a missing key or bad file is a ``ConfigError``."""
    if config.robot is None:
        raise ConfigError("robot: give the robot to use, e.g. robot=robots/four_wheeler.json")
    try:
        return load_robot(config.robot, config.limits)
    except (RobotFileError, InvalidRobotError) as err:
        raise ConfigError(f"robot: {err}") from None


def run_robots(run: Run) -> None:
    """Generate, save and picture ``robots.count`` random robots."""
    from evo.robot.gallery import write_gallery

    config = run.config
    rng = np.random.default_rng(config.seed)
    try:
        robots = random_robots(rng, config.robots.count, config.generator, config.limits)
    except ValueError as err:
        raise ConfigError(f"robots.count: {err}") from None
    write_gallery(robots, RunLayout(run.out).robots, config.physics, config.robots.render)


def run_train(run: Run) -> None:
    """Train one robot and evaluate it (``+exp=train``)."""
    from evo.learners.session import train_robot

    config = run.config
    learner = config.learner
    warn_if_failures_cannot_end(learner.total_steps, "learner.total_steps", learner, config.env)
    train_robot(_robot(config), config.training, seed=config.seed, out=run.out)


def run_evaluate(run: Run) -> None:
    """Evaluate a trained policy deterministically (``+exp=evaluate``)."""
    from evo.learners.session import evaluate_robot

    config = run.config
    if config.checkpoint is None:
        raise ConfigError(
            "checkpoint: give the policy to run, e.g. checkpoint=outputs/.../policy.pt"
        )
    try:
        evaluate_robot(_robot(config), Path(config.checkpoint), config.training,
                       seed=config.seed, out=run.out)
    except ValueError as err:
        raise ConfigError(f"checkpoint: {err}") from None


# ``${evo_method:${ga.structure},${learner.update},${ga.inheritance}}`` in configs, e.g. a
# sweep's subdir; ga.structure a letter (ga.structure=E,R) or its node
# (ga/structure=evolve,random); the third argument may be left out (inheritance off).
if not OmegaConf.has_resolver("evo_method"):
    OmegaConf.register_new_resolver(
        "evo_method", lambda structure, learns, inheritance="off": method_label(
            structure_letter(structure), learns, inheritance))


@dataclass(frozen=True)
class EvolveParts:
    """The typed objects an evolution run is made of (what ``task=evolve`` builds)."""

    ga: GAConfig
    strategy: StructureStrategy
    job: Job
    executor: EvalExecutor


def evolve_parts(config: EvoConfig, out: Path) -> EvolveParts:
    """Build and check everything ``task=evolve`` needs, before anything runs.

    Raises:
        ConfigError: naming the key of the first bad value.
    """
    learner, ga = config.learner, config.ga
    strategy = ga.strategy(config.generator, config.limits)
    method = method_label(strategy.code, learner.update, ga.inheritance)
    job = Job(config.physics, config.env, learner, str(out), method, record=config.record,
              config_yaml=config.yaml, timeout_s=ga.eval_timeout_s, early=ga.early_rejection)
    warn_if_failures_cannot_end(min(ga.expected_budgets()), "ga.schedule", learner, job.env)
    executor = config.make_executor()  # last: Ray starts here
    return EvolveParts(ga, strategy, job, executor)


@dataclass(frozen=True)
class EvolveCode:
    """The code ``task=evolve`` runs with, where the config chooses none: evo's own by
    default. Each is what a run calls, so one of another class changes what a run does
    at that seam and nothing else.

    Attributes:
        store: Makes the run's store from its directory (``evo.run.store.RunStore``, or
            a subclass: one that saves its files elsewhere too, or fails at a chosen
            write).
        evaluate: Trains one robot (``evo.evaluation.evaluate``, or a
            ``functools.partial`` of it with another ``learner``, ``open_recorder`` or
            ``save_policy``). Executors with worker processes pickle it: a module-level
            function, or a partial of one.
        run_log: Makes what mirrors every history row into ``run.mcap`` and ``run.rrd``
            (``evo.evolution.RunLog``, or a subclass).
    """

    store: Callable[[Path], RunStore] = RunStore
    evaluate: Callable[[Candidate, Job], Outcome] = evaluate
    run_log: Callable[[RunStore, RecordConfig, RunMetadata], RunLog] = RunLog

    @classmethod
    def with_seams(
        cls, *, open_recorder: OpenRecorder, save_policy: SavePolicy,
        store: Callable[[Path], RunStore] = RunStore,
        run_log: Callable[[RunStore, RecordConfig, RunMetadata], RunLog] = RunLog,
    ) -> EvolveCode:
        """evo's code with evaluations that open their recorders with ``open_recorder``
        and write their policies with ``save_policy`` (``evo.evaluation.evaluate``'s
        seams), and the given ``store`` and ``run_log``."""
        return cls(store=store, run_log=run_log,
                   evaluate=functools.partial(evaluate, open_recorder=open_recorder,
                                              save_policy=save_policy))


EVO_CODE = EvolveCode()
"""evo's own code of ``task=evolve``."""


def run_evolve(run: Run, code: EvolveCode = EVO_CODE) -> None:
    """The GA (``+exp=smoke``, ``demo``, ``paper_clean``, ...); ``resume=DIR`` continues.

    Everything is checked before anything is written: the config, and when the
    directory holds a run, its saved state (:meth:`evo.run.store.RunStore.load`) and a
    new ``ga.robot_budget`` given with ``resume=`` (:func:`check_robot_budget`). A
    resume that fails leaves the directory as it was. ``code`` makes the store, the
    run's log and the evaluations.
    """
    from evo.progress import evolution_progress, print_summary

    config, out = run.config, run.out
    store = code.store(out)
    saved = _state_to_continue(store, run.resuming)
    if run.started_ga is not None:
        check_robot_budget(run.started_ga, config.ga, saved)
    saved, dropped = _ending_at_budget(saved, config.ga.robot_budget, out)
    parts = keeping_its_method(evolve_parts(config, out), saved)
    if run.resuming:
        run.lock.claim()
        if run.started_ga is not None and run.started_ga.robot_budget != config.ga.robot_budget:
            _write_config(config.yaml, out, replacing=True)
            print(f"{out}: {ROBOT_BUDGET} changed from {run.started_ga.robot_budget} to "
                  f"{config.ga.robot_budget} robots")
    budgets = parts.ga.expected_budgets()
    log: RunLog | None = None
    evolution: Evolution | None = None
    try:
        with critical():  # opened whole, so the finally below can close it
            log = code.run_log(store, parts.job.record, {
                "config": parts.job.config_yaml, "seed": config.seed,
                "method": parts.job.method, "name": out.name})
        with evolution_progress(budgets, parts.job.method) as show:

            def on_result(row: HistoryRow) -> None:
                show(row)
                assert log is not None
                log(row)

            evolution = Evolution(store, ga=parts.ga, strategy=parts.strategy, job=parts.job,
                                  executor=parts.executor, seed=config.seed,
                                  on_result=on_result, evaluate=code.evaluate)
            if saved is not None:
                evolution.resume(saved)  # saved: the state without the robots dropped
                _discard(store, dropped, config.ga.robot_budget)
                show.resumed(evolution.history)
                for row in evolution.history:
                    log(row)
            summary = evolution.run()
    finally:
        if log is not None:
            history = evolution.history if evolution is not None else []
            log.close(history, parts.job.physics,
                      summary=evolution.summary() if evolution is not None else None)
    print_summary(summary, out)


def _ending_at_budget(saved: SavedState | None, robot_budget: int, out: Path
                      ) -> tuple[SavedState | None, list[Candidate]]:
    """``saved`` for a run of ``robot_budget`` robots, and the robots in flight it drops
    (:meth:`SavedState.ending_at`); a clear ``ConfigError`` if it cannot be one."""
    if saved is None:
        return None, []
    try:
        return saved.ending_at(robot_budget)
    except ValueError as err:
        raise ConfigError(f"{RunLayout(out).state}: {err}") from None


def _discard(store: RunStore, dropped: list[Candidate], robot_budget: int) -> None:
    """Remove the files of the robots in flight a resume dropped, naming each; called once
    the state without them is saved."""
    for candidate in dropped:
        store.discard(candidate.name)
        print(f"{store.root}: robot {candidate.name} (birth {candidate.birth}), in flight, "
              f"dropped: a run of {robot_budget} robots does not breed it")


def keeping_its_method(parts: EvolveParts, saved: SavedState | None) -> EvolveParts:
    """``parts`` with the method label the run's history already holds, so that every row
    of a run has one: a run with ``ga.inheritance`` on started before inheritance was
    part of the label (``E+L``, now ``E+L+I``) resumes as ``E+L``."""
    if saved is None or not saved.history or saved.history[0].method == parts.job.method:
        return parts
    return replace(parts, job=replace(parts.job, method=saved.history[0].method))


def _state_to_continue(store: RunStore, resuming: bool) -> SavedState | None:
    """The checked saved state of the run in ``store``, or None for a run that starts
    (a resume that stopped before its first result starts from the beginning)."""
    if store.has_state() or (resuming and store.evaluated_before()):
        return _saved_state(store)
    if resuming:
        print(f"{store.root}: no robot was evaluated before the run stopped (no "
              f"{store.layout.state.name} yet); starting it from the beginning",
              file=sys.stderr)
    return None


def _saved_state(store: RunStore) -> SavedState:
    """The checked state of the run in ``store``; a clear ``ConfigError`` otherwise."""
    run_dir = store.root
    if not store.has_state():
        found = store.leftovers()
        held = f" It holds {' and '.join(found)} of an earlier run." if found else ""
        raise ConfigError(
            f"resume: {run_dir} has no {store.layout.state.name}, so there is no run to "
            f"continue.{held} To start afresh, choose a new hydra.run.dir (or empty "
            f"{run_dir} first)")
    try:
        return store.load()
    except ValueError as err:
        raise ConfigError(f"resume: {err}") from None


def check_robot_budget(started: GAConfig, ga: GAConfig, saved: SavedState | None) -> None:
    """Whether a resumed run started with ``started`` may end at ``ga.robot_budget``
    instead (``resume=DIR ga.robot_budget=N``): before or after the end it was started
    with; at the robots already evaluated, it ends at once, and the robots in flight
    born at N or later are dropped (:meth:`SavedState.ending_at`).

    Raises:
        ConfigError: N is not above the birth of every robot already evaluated
            (``saved``), or would give one of the robots it keeps another training
            budget: ``ga.schedule`` may depend on ``ga.robot_budget``, and the robots of
            one run are those of a run of N.
    """
    history = saved.history if saved is not None else []
    evaluated = max((row.birth for row in history), default=-1) + 1
    if ga.robot_budget < evaluated:
        raise ConfigError(
            f"{ROBOT_BUDGET}: the run has evaluated robots up to birth {evaluated - 1}, "
            f"which it cannot un-evaluate; expected at least {evaluated}, got "
            f"{ga.robot_budget}")
    kept = min(saved.next_birth if saved is not None else 0, ga.robot_budget)
    was, now = started.budgets()[:kept], ga.budgets()[:kept]
    changed = [b for b in range(kept) if was[b] != now[b]]
    if changed:
        b = changed[0]
        raise ConfigError(
            f"{ROBOT_BUDGET}: ga.schedule (initial {ga.schedule.initial}, first "
            f"{ga.schedule.first}, last {ga.schedule.last}) depends on {ROBOT_BUDGET}, so "
            f"{ga.robot_budget} instead of {started.robot_budget} would give robot {b}, "
            f"already born, {now[b]} env steps instead of {was[b]} ({len(changed)} of the "
            f"{kept} born would change): the robots evaluated and those to come would not be "
            f"one run of {ga.robot_budget} robots; keep {ROBOT_BUDGET}={started.robot_budget} "
            "(a schedule with first = last takes any)")


ROBOT_BUDGET = "ga.robot_budget"
"""The one key ``resume=DIR`` of ``task=evolve`` takes a new value of
(:func:`with_robot_budget`): a run stops early for good, or goes on past its end."""


def _given(key: str) -> bool:
    """Whether the command line sets ``key`` (``key=value``)."""
    return any(o.partition("=")[0] == key for o in HydraConfig.get().overrides.task)


def _resumed_config(run_dir: Path, takes: tuple[str, ...] = ()) -> DictConfig:
    """The resolved config a run directory was started with (:func:`evo.edge.typed_config`
    reads an older evo's in today's form). The command line may set only the keys in
    ``takes`` besides ``resume=``; the caller applies them."""
    path = RunLayout(run_dir).config
    if not path.is_file():
        raise ConfigError(f"resume: {path} not found; is {run_dir} an evo run directory?")
    extra = [o for o in HydraConfig.get().overrides.task
             if not o.startswith("resume=") and o.partition("=")[0] not in takes]
    if extra:
        but = "".join(f" but for {key}=..." for key in takes)
        raise ConfigError(
            f"resume: a resumed run keeps the config it was started with ({path}){but}; "
            f"drop the other overrides: {' '.join(extra)}"
        )
    loaded = OmegaConf.load(path)
    assert isinstance(loaded, DictConfig)
    loaded.resume = None
    return loaded


def _write_config(text: str, out: Path, lock: RunLock | None = None, *,
                  replacing: bool = False) -> None:
    """Save the resolved config ``text`` in the run directory (after ``lock.claim()``).

    A directory that already holds an evolution state (the same command run again, e.g.
    a requeued cluster job or a stopped sweep started again with the same
    ``hydra.sweep.dir``) is continued only when the config is the same; anything else
    would mix two runs in one directory, and is refused before anything is written.
    ``replacing`` writes over it: the config of a resumed run, changed as ``resume=``
    allows (:func:`check_robot_budget`).
    """
    layout = RunLayout(out)
    path = layout.config
    if (not replacing and layout.state.exists() and path.is_file()
            and path.read_text() != text):
        raise ConfigError(
            f"hydra.run.dir: {out} already holds a run with another config; continue it "
            f"with resume={out}, or choose a new output directory"
        )
    if lock is not None:
        lock.claim()
    write_text(path, text)


def run_noise_sweep(run: Run) -> tuple[float, float]:
    """One trial of ``+exp=noise_sweep`` (``evo.sweep``): the retraining of the sweep's
    fixed sample under the trial's config; returns its agreement between seeds and
    core-seconds per robot to the Optuna sweeper."""
    from evo.sweep import SweepSettings, record_trial, trial_result

    config = run.config
    sweep = config.noise_sweep if config.noise_sweep is not None else SweepSettings()
    retrain = RetrainConfig(random=sweep.robots, seeds=sweep.seeds, budget=sweep.budget,
                            baseline=False)
    overrides = trial_overrides()
    try:
        retraining_ = retraining(config, run.out, retrain, root_seed=sweep.robot_seed,
                                 overrides=overrides)
    except RetrainError as err:
        raise ConfigError(f"noise_sweep: {err}") from None
    trainings = run_trainings(retraining_, EvaluationPool(config.make_executor()))
    return record_trial(run.out, trial_result(trainings, sweep, overrides, run.out)).values()


def run_retrain(run: Run) -> None:
    """Train fixed structures under independent seeds (``+exp=retrain``, the noise
    ceiling; ``+exp=designer``, the designer comparison): ``evo.retrain``.
    ``resume=DIR`` continues, reusing the finished trainings (so does the same command
    run again). ``config.yaml`` is written once the folder is known to hold no
    trainings of other settings. The reports are ``analysis``'s."""
    config, out = run.config, run.out
    if config.retrain is None:
        raise ConfigError("retrain: no structures to train; start from +exp=retrain or "
                          "+exp=designer")
    try:
        stored = read_retrain_settings(RetrainLayout(out).settings) if run.resuming else None
        overrides = stored.overrides if stored is not None else trial_overrides()
        retraining_ = retraining(config, out, config.retrain, root_seed=config.seed,
                                 overrides=overrides)
    except (RetrainError, ValueError) as err:  # ValueError: an unreadable settings.json
        raise ConfigError(str(err)) from None
    if run.resuming:
        run.lock.claim()
    else:
        _write_config(config.yaml, out, run.lock)
    trainings = run_trainings(retraining_, EvaluationPool(config.make_executor()))
    if not config.retrain.evaluate:
        print(f"noise ceiling: {ceiling_line(agreement(trainings))}")
    report = "analysis.designer" if config.retrain.evaluate else "analysis.noise_ceiling"
    print(f"{len(trainings)} trainings in {out}; report: python -m {report} {out}")


TASKS: dict[str, Callable[[Run], object]] = {
    "evolve": run_evolve,
    "robots": run_robots,
    "train": run_train,
    "evaluate": run_evaluate,
    "noise_sweep": run_noise_sweep,
    "retrain": run_retrain,
}
RESUMABLE = ("evolve", "retrain")
"""The tasks ``resume=DIR`` continues."""
WRITES_ITS_CONFIG = ("retrain",)
"""The tasks that write ``config.yaml`` themselves, once their folder is checked."""


def start(cfg: DictConfig, name: str, out: Path, lock: RunLock) -> Run:
    """The run of task ``name``: ``cfg`` typed once, or with ``resume=DIR`` the config
    DIR was started with (an evolution's with the new ``ga.robot_budget`` given); a
    new run's ``config.yaml`` written.

    Raises:
        ConfigError: naming the key of the first bad value.
    """
    if cfg.resume is None:
        config = typed_config(cfg)
        if name not in WRITES_ITS_CONFIG:
            _write_config(config.yaml, out, lock)
        return Run(config, out, lock)
    takes = (ROBOT_BUDGET,) if name == "evolve" else ()
    stored = _resumed_config(Path(str(cfg.resume)), takes=takes)
    if not (takes and _given(ROBOT_BUDGET)):
        return Run(typed_config(stored), out, lock, resuming=True)
    started = typed(GAConfig, current(stored).ga, "ga")
    changed = copy.deepcopy(stored)
    changed.ga.robot_budget = cfg.ga.robot_budget
    return Run(typed_config(changed), out, lock, resuming=True, started_ga=started)


def main(cfg: DictConfig, code: EvolveCode = EVO_CODE) -> object:
    """Dispatch on ``task`` in a run directory this process owns (``evo.run.files``);
    ``task=evolve`` runs with ``code``.

    A bad config value, or a directory another process holds, ends the run with one
    clear line (exit 2). SIGINT or SIGTERM stop it cleanly (``evo.interrupt``): the
    evaluations in flight are stopped, the state and recordings are kept, and one line
    says how to continue (exit 130 or 143). A write that fails for want of room (a full
    disk or quota, a file-size limit) ends it with one line naming the file and the
    cause (exit 1); it resumes once there is room (``evo.run.files``).
    """
    out = Path(HydraConfig.get().runtime.output_dir)
    lock = RunLock(out)
    # A log file that can no longer be written (a full disk) must not print a traceback
    # per message and bury the one line that says why the run stopped.
    logging.raiseExceptions = False
    try:
        with handle_signals(), lock:
            name = _resumable_task(cfg)
            task = TASKS.get(name)
            if task is None:
                raise ConfigError(
                    f"task: unknown task {cfg.task!r}; expected one of {sorted(TASKS)}")
            run = start(cfg, name, out, lock)
            torch.set_num_threads(run.config.torch_threads)
            if task is run_evolve:  # the one task whose code a caller may choose
                task = functools.partial(run_evolve, code=code)
            return task(run)  # a sweeper's objectives (noise_sweep), else None
    except (ConfigError, RunDirectoryBusy) as err:
        prefix = "bad config: " if isinstance(err, ConfigError) else ""
        print(f"error: {prefix}{err}", file=sys.stderr)
        sys.exit(2)
    except Exception as err:
        # A full disk (or quota, or file-size limit): the state on disk is the last one
        # written whole. The first file that failed is named (closing the others on the
        # way out fails too), in one line.
        if (full := write_failure(err)) is None:
            raise
        print(f"error: {full}; {_how_to_continue(cfg, out, 'make room, then ')}",
              file=sys.stderr)
        sys.exit(1)
    except (Interrupted, KeyboardInterrupt) as stop:
        status = stop.exit_code if isinstance(stop, Interrupted) else 130
        print(f"interrupted; {_how_to_continue(cfg, out)}", file=sys.stderr)
        sys.exit(status)


def _task_name(cfg: DictConfig) -> str:
    """The task to run: ``task``, or with ``resume=DIR`` the task DIR was started with."""
    if cfg.resume is None:
        return str(cfg.task)
    path = RunLayout(Path(str(cfg.resume))).config
    stored = OmegaConf.load(path) if path.is_file() else None
    return str(stored.get("task", "evolve")) if isinstance(stored, DictConfig) else "evolve"


def _resumable_task(cfg: DictConfig) -> str:
    """:func:`_task_name`, refusing ``resume=`` of a task that does not resume."""
    name = _task_name(cfg)
    if cfg.resume is not None and name not in RESUMABLE:
        raise ConfigError(f"resume: {cfg.resume} holds a task={name} run, which does not "
                          f"resume (only {' and '.join(RESUMABLE)} do); run its command again")
    return name


def _how_to_continue(cfg: DictConfig, out: Path, first: str = "") -> str:
    """How a stopped run goes on: its resume command, or that its directory is incomplete."""
    if _task_name(cfg) in RESUMABLE:
        return f"{first}continue with: python evo/main.py resume={out}"
    return f"{out} is incomplete"


def _check_run_dir_arg(argv: list[str]) -> None:
    """A ``hydra.run.dir=`` that cannot be a run directory (an existing file, a place
    that cannot be created, or one another process holds) ends here with one line,
    before Hydra would fail on it or write into it."""
    for arg in argv:
        if not arg.startswith("hydra.run.dir="):
            continue
        run_dir = Path(arg.split("=", 1)[1])
        problem = None
        if run_dir.is_dir() and is_locked(run_dir):  # before Hydra writes its .hydra/ there
            print(f"error: {busy_message(run_dir)}", file=sys.stderr)
            sys.exit(2)
        if run_dir.exists() and not run_dir.is_dir():
            problem = "exists and is not a directory"
        elif run_dir.is_dir() and not os.access(run_dir, os.W_OK | os.X_OK):
            problem = "is not writable"
        else:
            try:  # what Hydra would do next
                run_dir.mkdir(parents=True, exist_ok=True)
            except OSError as err:
                problem = f"cannot be created ({err.strerror or err})"
        if problem:
            print(f"error: bad config: hydra.run.dir: {run_dir} {problem}", file=sys.stderr)
            sys.exit(2)


def _resume_in_place(argv: list[str]) -> list[str]:
    """``resume=DIR`` runs in DIR itself: Hydra writes nothing anywhere else.

    A DIR that is not a run directory ends here, before Hydra would create it.
    """
    for arg in argv:
        if arg.startswith("resume=") and arg != "resume=null":
            run_dir = arg.split("=", 1)[1]
            if not RunLayout(Path(run_dir)).config.is_file():
                print(
                    f"error: bad config: resume: {run_dir} is not an evo run directory "
                    "(no config.yaml)",
                    file=sys.stderr,
                )
                sys.exit(2)
            return [*argv, f"hydra.run.dir={run_dir}", "hydra.output_subdir=null",
                    "hydra/job_logging=disabled"]
    return argv


def cli(code: EvolveCode = EVO_CODE) -> None:
    """``python evo/main.py [overrides]``: the command line in ``sys.argv``, through
    Hydra (its config tree is ``conf/``), with ``code`` for ``task=evolve``.

    A script that runs evo with code of its own sets ``sys.argv`` to the command line
    (``[".../evo/main.py", *overrides]``) and calls this.
    """
    _check_run_dir_arg(sys.argv[1:])
    sys.argv = _resume_in_place([sys.argv[0], *older_overrides(sys.argv[1:])])

    @hydra.main(version_base="1.3", config_path=str(CONF_DIR), config_name="config")
    def run(cfg: DictConfig) -> object:
        return main(cfg, code)

    run()


if __name__ == "__main__":
    cli()
