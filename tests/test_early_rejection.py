"""Early rejection: the stopping rule on planted curves, inside a real evaluation, in the
evolution (a stopped offspring never enters the population and is recorded with its
steps), across a kill and resume, and off by default."""

from __future__ import annotations

import dataclasses
import json
import math
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from test_evolution import (
    TINY,
    comparable,
    fake_evaluate,
    killed,
    main_cmd,
    make_evolution,
    read_history,
    run,
)

from evo.early_rejection import Curve, EarlyRejection, StoppingRule, predict, replay_rule
from evo.envs.params import EnvConfig
from evo.envs.tasks.reach import Reach
from evo.evaluation import Job, Outcome, evaluate
from evo.learners.ppo import PPO
from evo.robot import load_robot
from evo.robot.builder import PhysicsParams
from evo.run.records import Candidate

RULE = EarlyRejection(enabled=True, checkpoints=(0.2, 0.35, 0.5), margin=0.1)


def rows(returns: list[float], budget: int = 10_000, episodes: int = 4) -> list[dict[str, float]]:
    """A learning curve of len(returns) batches spread evenly over ``budget``."""
    steps = np.linspace(budget / len(returns), budget, len(returns))
    return [{"env_steps": float(s), "train/episodes": float(episodes), "train/mean_return": r}
            for s, r in zip(steps, returns, strict=True)]


# ---------------------------------------------------------------- the rule


def test_a_curve_that_plainly_cannot_beat_the_minimum_stops_at_the_first_checkpoint() -> None:
    rule = StoppingRule(RULE, 10_000, threshold=0.5)
    stopped_at = next(i for i, row in enumerate(rows([-1.0] * 20)) if rule(row))
    assert rows([-1.0] * 20)[stopped_at]["env_steps"] == 2_000, "the first batch past 20 %"
    (verdict,) = rule.verdicts
    assert verdict.fraction == 0.2 and verdict.stop and verdict.predicted == pytest.approx(-1.0)


def test_a_curve_that_beats_the_minimum_is_never_stopped() -> None:
    rising = list(np.linspace(-0.5, 1.0, 20))
    rule = StoppingRule(RULE, 10_000, threshold=-0.6)
    assert not any(rule(row) for row in rows(rising))
    assert [v.fraction for v in rule.verdicts] == [0.2, 0.35, 0.5] and not any(
        v.stop for v in rule.verdicts)
    nothing_to_beat = StoppingRule(RULE, 10_000, threshold=math.nan)
    assert not any(nothing_to_beat(row) for row in rows([-1.0] * 20))


def test_the_margin_spares_a_curve_just_below_the_minimum() -> None:
    flat = rows([-0.55] * 20)
    assert any(StoppingRule(dataclasses.replace(RULE, margin=0.0), 10_000, -0.5)(r)
               for r in flat)
    assert not any(StoppingRule(RULE, 10_000, -0.5)(r) for r in flat)


def test_the_rule_follows_an_updated_minimum() -> None:
    minimum = [-2.0]
    rule = StoppingRule(RULE, 10_000, threshold=lambda: minimum[0])
    curve = rows([-1.0] * 20)
    assert not any(rule(row) for row in curve[:5])  # 20 %: -1.0 beats -2.0
    minimum[0] = 0.0  # the population improved meanwhile
    assert any(rule(row) for row in curve[5:])
    assert rule.verdicts[-1].fraction == 0.35


def test_the_offline_replay_agrees_with_the_online_rule() -> None:
    curve = rows(list(np.linspace(-1.0, -0.2, 20)))
    online = StoppingRule(RULE, 10_000, threshold=-0.3)
    stop = next((row["env_steps"] for row in curve if online(row)), None)
    offline = replay_rule(RULE, Curve.from_rows(pd.DataFrame(curve)), 10_000, -0.3)
    assert offline is not None and stop is not None
    assert offline.fraction == online.verdicts[-1].fraction
    assert offline.predicted == pytest.approx(online.predicted)


@pytest.mark.parametrize("predictor", ["value", "area", "curve"])
def test_every_predictor_predicts_on_the_return_scale(predictor: str) -> None:
    curve = Curve.from_rows(pd.DataFrame(rows([-1.0] * 20)))
    assert predict(curve, 10_000, 0.5, predictor) == pytest.approx(-1.0, abs=1e-6)
    assert math.isnan(predict(curve, 10_000, 0.01, predictor)), "no episode before the cut"


def rated(rate: float, batches: int = 20, budget: int = 10_000) -> list[dict[str, float]]:
    """A curve in which no episode ends (long episodes) and every batch earns ``rate``
    per env step, split over two reward terms."""
    return [{**row, "train/episodes": 0.0, "train/mean_return": math.nan,
             "train/reward/time": -0.001, "train/reward/approach": rate + 0.001}
            for row in rows([0.0] * batches, budget)]


def test_the_rate_predictor_needs_no_finished_episode() -> None:
    curve = Curve.from_rows(pd.DataFrame(rated(-0.0009)))
    assert math.isnan(predict(curve, 10_000, 0.3, "value")), "value waits for an episode"
    assert predict(curve, 10_000, 0.3, "rate", t_max=1000) == pytest.approx(-0.9)
    with pytest.raises(ValueError, match="needs the task's t_max"):
        predict(curve, 10_000, 0.3, "rate")
    rule = StoppingRule(dataclasses.replace(RULE, predictor="rate"), 10_000, threshold=-0.5,
                        t_max=1000)
    stopped_at = next(i for i, row in enumerate(rated(-0.0009)) if rule(row))
    assert rated(-0.0009)[stopped_at]["env_steps"] == 2_000, "stopped at the first checkpoint"
    spared = StoppingRule(dataclasses.replace(RULE, predictor="rate"), 10_000, threshold=-0.5,
                          t_max=1000)
    assert not any(spared(row) for row in rated(0.0002)), "a rate of +0.2 an episode beats it"


def test_the_rate_reads_the_last_batches_before_the_cut() -> None:
    table = pd.DataFrame(rated(-0.001)[:10] + rated(0.001)[10:])  # a jump half-way
    curve = Curve.from_rows(table)
    assert predict(curve, 10_000, 0.45, "rate", last=3, t_max=100) == pytest.approx(-0.1)
    assert predict(curve, 10_000, 0.65, "rate", last=3, t_max=100) == pytest.approx(0.1)
    assert predict(curve, 10_000, 0.55, "rate", last=2, t_max=100) == pytest.approx(0.0)


@pytest.mark.parametrize(("change", "message"), [
    (dict(checkpoints=(0.5, 1.5)), "checkpoints must be fractions"),
    (dict(checkpoints=(0.5, 0.2)), "checkpoints must rise"),
    (dict(predictor="slope"), "predictor must be one of value, area, curve"),
    (dict(margin=-0.1), "margin >= 0"),
])
def test_bad_settings_are_named(change: dict[str, object], message: str) -> None:
    with pytest.raises(ValueError, match=message):
        EarlyRejection(**change)  # type: ignore[arg-type]


# ---------------------------------------------------------------- a real evaluation

NEAR = EnvConfig(task=Reach(t_max=40))
TINY_LEARNER = PPO(num_envs=4, rollout_steps=64, epochs=1, minibatch_size=128,
                             hidden=(32, 32))


def real_candidate(threshold: float) -> Candidate:
    robot = load_robot("robots/four_wheeler.json")
    return Candidate(5, robot.name, robot.canonical_json(), 2560, 11, ("a", "b"), "crossover",
                threshold)


@pytest.mark.parametrize(("threshold", "stops", "predictor"), [
    (5.0, True, "value"), (-10.0, False, "value"), (5.0, True, "rate")])
def test_a_real_training_stops_only_when_it_cannot_win(
    tmp_path: Path, threshold: float, stops: bool, predictor: str
) -> None:
    rule = dataclasses.replace(RULE, predictor=predictor)
    job = Job(PhysicsParams(), NEAR, TINY_LEARNER, str(tmp_path), early=rule)
    outcome = evaluate(real_candidate(threshold), job)
    assert outcome.error is None, outcome.error
    assert outcome.stopped_early is stops
    if stops:  # the first batch at or past 20 % of 2,560 steps: the 2nd of 256 steps
        assert outcome.env_steps == 512 and math.isfinite(outcome.predicted)
        curve = pd.read_csv(tmp_path / "evals" / f"{real_candidate(threshold).name}.csv")
        assert curve["env_steps"].max() == 512
    else:
        assert outcome.env_steps >= 2560


# ---------------------------------------------------------------- in the evolution


def test_a_stopped_offspring_never_enters_the_population(tmp_path: Path) -> None:
    def stops_every_third(candidate: Candidate, job: Job) -> Outcome:
        outcome = fake_evaluate(candidate, job)
        if candidate.parents and candidate.birth % 3 == 0:
            assert math.isfinite(candidate.threshold), "an offspring knows what it must beat"
            return dataclasses.replace(outcome, fitness=9.0, env_steps=candidate.budget // 5,
                                       stopped_early=True, predicted=8.5)
        return outcome

    evolution = make_evolution(tmp_path, evaluate=stops_every_third)
    evolution.job = dataclasses.replace(evolution.job, early=RULE)
    summary = evolution.run()
    history = read_history(tmp_path)
    stopped = history[history["status"] == "stopped-early"]
    assert len(stopped) >= 3
    assert not stopped["accepted"].any() and (stopped["replaced"] == "").all()
    assert (stopped["env_steps"] == stopped["budget"] // 5).all(), "recorded with its steps"
    assert (pd.to_numeric(stopped["predicted"]) == 8.5).all()
    population = {m["name"] for m in json.loads((tmp_path / "population.json").read_text())[
        "population"]}
    assert not population & set(stopped["name"])
    assert summary.best_fitness < 9.0, "a stopped robot is never named best"
    assert summary.stopped_early == len(stopped)
    assert summary.env_steps_saved == int((stopped["budget"] - stopped["env_steps"]).sum())


EARLY = [*TINY, "ga.robot_budget=8", "ga.schedule.initial=1024", "ga.schedule.first=2048",
         "ga.schedule.last=2048", "ga.early_rejection.enabled=true",
         "ga.early_rejection.margin=0", "ga.early_rejection.checkpoints=[0.3]",
         "executor=serial"]
"""A tiny serial run in which the early-rejection rule stops several offspring."""


@pytest.fixture(scope="module")
def early_reference(tmp_path_factory: pytest.TempPathFactory) -> Path:
    run_dir = tmp_path_factory.mktemp("early") / "run"
    done = run(main_cmd(*EARLY, f"hydra.run.dir={run_dir}"), run_dir.parent)
    assert done.returncode == 0, done.stderr[-3000:]
    history = read_history(run_dir)
    assert (history["status"] == "stopped-early").sum() >= 2, "the rule stops offspring"
    return run_dir


@pytest.mark.slow
@pytest.mark.long  # SIGKILL and resume of the loop itself: test_evolution
def test_resume_after_a_kill_during_an_early_stopped_evaluation(
    early_reference: Path, tmp_path: Path
) -> None:
    history = read_history(early_reference)
    first_stopped = int(history.loc[history["status"] == "stopped-early", "birth"].min())
    run_dir = tmp_path / "run"
    # The checkpoint is saved after training stopped: killed there, the stopped robot is
    # still in flight, and is evaluated (and stopped) again on resume.
    killed("checkpoint", first_stopped + 1, *EARLY, f"hydra.run.dir={run_dir}", cwd=tmp_path)
    (in_flight,) = json.loads((run_dir / "state.json").read_text())["pending"]
    assert in_flight["birth"] == first_stopped
    done = run(main_cmd(f"resume={run_dir}"), tmp_path)
    assert done.returncode == 0, done.stderr[-3000:]
    pd.testing.assert_frame_equal(comparable(read_history(run_dir)), comparable(history))


# ---------------------------------------------------------------- off by default

sys.path.insert(0, str(Path(__file__).resolve().parent / "data" / "golden"))
import make_golden  # noqa: E402
from numerics import assert_same_history  # noqa: E402


@pytest.mark.slow
@pytest.mark.parametrize("name", [  # one paper config by default, every one in the long tier
    pytest.param(name, marks=[] if name == "paper_clean" else [pytest.mark.long])
    for name in sorted(make_golden.RUNS)])
def test_off_by_default_every_paper_config_gives_the_history_of_before(
    tmp_path: Path, name: str
) -> None:
    """Early rejection is off in every paper config, and off it changes nothing: a tiny
    serial run of each gives the history recorded before the feature existed
    (``tests/data/golden/``), cell for cell on a machine with the arithmetic it was
    recorded with (``tests/numerics.py``)."""
    golden = pd.read_csv(make_golden.HERE / f"{name}.csv", dtype=str, keep_default_na=False)
    assert_same_history(make_golden.history(name, tmp_path), golden, make_golden.HERE,
                        population=make_golden.POPULATION)
    config = (tmp_path / name / "config.yaml").read_text()
    assert "early_rejection:\n    enabled: false" in config


# ---------------------------------------------------------------- analysis and calibration


@pytest.mark.slow
def test_the_report_and_the_early_slope_study_leave_stopped_robots_out_and_say_so(
    early_reference: Path,
) -> None:
    from analysis.ablation.report import ablation_tables
    from analysis.early_slope.report import study_robots
    from analysis.load import load_runs
    from analysis.stats import Resampling

    robots = load_runs([early_reference]).robots
    stopped = robots[robots["status"] == "stopped-early"]
    assert len(stopped) >= 2 and stopped["predicted"].notna().all()
    tables = ablation_tables(robots, Resampling.seeded(0, 50))
    assert any(f"{len(stopped)} robot(s) stopped early" in note for note in tables.notes)
    assert (tables.summary["n"] == len(robots) - len(stopped)).all(), tables.summary
    chosen, _, note = study_robots(robots)
    assert not set(chosen["name"]) & set(stopped["name"]) and "stopped early" in note


@pytest.mark.slow
def test_the_offline_replay_makes_the_decisions_the_run_made(early_reference: Path) -> None:
    from analysis.load import load_runs
    from analysis.rejection import replay

    runs = load_runs([early_reference])
    rule = EarlyRejection(enabled=True, checkpoints=(0.3,), margin=0.0)
    offspring = replay(runs.robots, runs.curves, runs.population_sizes, rule)
    status = runs.robots.set_index("name")["status"]
    assert len(offspring) >= 4
    assert (offspring["stopped"] == (status[offspring["name"]] == "stopped-early").to_numpy()
            ).all(), offspring


@pytest.mark.slow
def test_the_equal_cost_report_counts_what_the_run_with_the_rule_saved_and_kept(
    early_reference: Path, serial_reference: Path, tmp_path: Path
) -> None:
    """``analysis.equal_cost`` on a run with the rule and one without: its per-run
    figures are the runs' own (summary.json, population.json), a stopped robot is never
    a best or a member, and the report and figure are written."""
    from analysis.equal_cost.early_rejection import main

    assert main(["--without", str(serial_reference), "--with", str(early_reference),
                 "--out", str(tmp_path)]) == 0
    table = pd.read_csv(tmp_path / "equal_cost_runs.csv").set_index("side")
    for side, run_dir in (("with", early_reference), ("without", serial_reference)):
        summary = json.loads((run_dir / "summary.json").read_text())
        members = [m["fitness"] for m in json.loads(
            (run_dir / "population.json").read_text())["population"]]
        row = table.loc[side]
        assert row["env_steps"] == summary["env_steps"]
        assert row["saved"] == summary["env_steps_saved"]
        assert row["stopped_early"] == summary["stopped_early"]
        assert row["best"] == pytest.approx(summary["best_fitness"])
        assert row["pop_mean"] == pytest.approx(np.mean(members))
        assert row["pop_min"] == pytest.approx(min(members))
    assert table.loc["with", "stopped_early"] >= 2
    report = (tmp_path / "equal_cost.md").read_text()
    assert "## At equal cost" in report and "Mann–Whitney" in report
    # the run without reaches its own final best by its end, at a ratio of at most 1
    section = report.split("## Env steps to the final best")[1].split("##")[0]
    assert f"| {summary['best_fitness']:.3f} | {table.loc['without', 'env_steps']} |" in section
    assert (tmp_path / "equal_cost.png").read_bytes()[:4] == b"\x89PNG"


def test_the_run_without_the_rule_is_read_at_the_env_steps_the_run_with_it_spent() -> None:
    from analysis.equal_cost import at_env_steps

    trace = pd.DataFrame(dict(run="a", env_steps=[10, 20, 30, 40],
                              pop_max=[0.1, 0.2, 0.3, 0.4]))
    row, evaluated = at_env_steps(trace, "a", 35)
    assert (row["pop_max"], evaluated) == (0.3, 3)
    row, evaluated = at_env_steps(trace, "a", 5)
    assert (row["pop_max"], evaluated) == (0.1, 1), "before its first robot: the first"


def test_the_paired_runs_part_where_their_robots_first_differ() -> None:
    from analysis.equal_cost.early_rejection import parting_table
    from analysis.load import Runs

    def runs(names: list[str], status: list[str]) -> Runs:
        robots = pd.DataFrame(dict(seed=0, birth=range(len(names)), name=names,
                                   status=status))
        return Runs(robots, pd.DataFrame(), pd.DataFrame())

    without = runs(["a", "b", "c", "d"], ["trained"] * 4)
    with_ = runs(["a", "b", "x", "y"], ["trained", "stopped-early", "trained", "trained"])
    (row,) = parting_table(without, with_).to_dict("records")
    assert row == dict(seed=0, same_first_births=2, first_stop=1)


def test_a_stop_is_judged_by_the_paired_full_training_up_to_the_first_wrong_one() -> None:
    """Offspring stopped with the rule are judged by the run without it, which trained
    the same robot at the same birth in full: a stop of an offspring it rejected is
    right, one it accepted is wrong, and nothing after the first wrong stop (where the
    populations part) or after the runs' robots differ is judged."""
    from analysis.equal_cost.early_rejection import stopped_against_full
    from analysis.load import Runs
    from analysis.stats import wilson

    def runs(names: str, status: list[str], accepted: str) -> Runs:
        robots = pd.DataFrame(dict(
            seed=0, birth=range(len(names)), name=list(names), status=status,
            operator=["random"] * 2 + ["mutation"] * (len(names) - 2),
            accepted=[c == "1" for c in accepted]))
        return Runs(robots, pd.DataFrame(), pd.DataFrame())

    trained, stopped = "trained", "stopped-early"
    #              initial  a: right stop  b: accepted  c: wrong stop  d: after it
    without = runs("ijabcde", [trained] * 7, "1101111")
    with_ = runs("ijabcdx", [trained, trained, stopped, trained, stopped, stopped,
                             trained], "1100000")
    (row,) = stopped_against_full(without, with_).to_dict("records")
    assert row == dict(seed=0, births=3, accepted=2, stopped=2, wrongly_stopped=1)

    parted = runs("ijaXcde", [trained, trained, stopped] + [trained] * 4, "1100000")
    (row,) = stopped_against_full(without, parted).to_dict("records")
    assert row == dict(seed=0, births=1, accepted=0, stopped=1, wrongly_stopped=0)

    rate, low, high = wilson(1, 20)
    assert rate == 0.05 and 0 < low < 0.05 < high < 0.3


@pytest.mark.slow
def test_the_equal_cost_report_over_each_runs_first_robots_counts_only_those(
    early_reference: Path, serial_reference: Path, tmp_path: Path
) -> None:
    """``--first N`` compares the runs over their first N robots: each side counts N
    robots, and its env steps are what those robots were trained for."""
    from analysis.equal_cost.early_rejection import main

    first = 4
    assert main(["--without", str(serial_reference), "--with", str(early_reference),
                 "--out", str(tmp_path), "--first", str(first)]) == 0
    table = pd.read_csv(tmp_path / "equal_cost_runs.csv").set_index("side")
    for side, run_dir in (("with", early_reference), ("without", serial_reference)):
        history = pd.read_csv(run_dir / "history.csv")
        assert len(history) > first, run_dir
        assert table.loc[side, "robots"] == first
        assert table.loc[side, "env_steps"] == history.nsmallest(first, "birth")[
            "env_steps"].sum()
