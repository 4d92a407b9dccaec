"""The run package (``evo/run/``): its records read back what they wrote, files of older
runs still read, and a run directory made by an earlier version of evo resumes."""

from __future__ import annotations

import dataclasses
import json
import math
import shutil
import subprocess
import sys
from pathlib import Path

import pandas as pd
import pytest
from numerics import assert_same_history

from evo.run.layout import RunLayout, TrainLayout
from evo.run.records import (
    HISTORY_COLUMNS,
    TRAINING_COLUMNS,
    HistoryRow,
    RetrainSettings,
    RunSummary,
    SweepTrial,
    TrainingRow,
    TrainSummary,
    read_history,
    read_retrain_settings,
    read_run_summary,
    read_sweep_trial,
    read_train_summary,
    read_trainings,
    write_history,
    write_retrain_settings,
    write_run_summary,
    write_sweep_trial,
    write_train_summary,
    write_trainings,
)
from evo.run.store import RunStore

REPO = Path(__file__).resolve().parents[1]
OLD_RUN = REPO / "tests" / "data" / "run_58aad82"
"""A serial run made by evo at commit 58aad82 and stopped after its fourth robot
(``stopped``), and the history of the same run left to finish (``whole_history.csv``)."""


def row(birth: int, fitness: float, parents: tuple[str, ...] = (), **extra: object) -> HistoryRow:
    fields: dict[str, object] = dict(
        birth=birth, name=f"robot-{birth}", method="E+L", parents=parents,
        operator="crossover" if parents else "random", budget=100, seed=birth,
        fitness=fitness, accepted=True, replaced="", env_steps=100, episodes=2,
        wall_seconds=0.5, error="", population_best=fitness, population_mean=fitness,
        status="trained", predicted=math.nan)
    return HistoryRow(**{**fields, **extra})  # type: ignore[arg-type]


def test_history_reads_back_what_it_wrote_and_old_files_without_threshold(
    tmp_path: Path,
) -> None:
    rows = [row(0, 0.5), row(1, 0.25),
            row(2, 0.75, ("robot-0", "robot-1"), threshold=0.25, predicted=0.6,
                inherited_from="robot-1")]
    path = write_history(tmp_path / "history.csv", rows)
    table = read_history(path)
    assert tuple(table.columns) == HISTORY_COLUMNS and HISTORY_COLUMNS[-1] == "eval_mean_return"
    back = [HistoryRow.from_record(r) for r in table.to_dict("records")]
    assert back[2] == rows[2] and back[0].parents == () and math.isnan(back[0].threshold)
    assert back[0].inherited_from == "" and back[2].inherited_from == "robot-1"
    table.drop(columns=["threshold", "status", "predicted", "inherited_from",
                        "eval_success_rate", "eval_mean_return"]).to_csv(path, index=False)
    old = [HistoryRow.from_record(r) for r in read_history(path).to_dict("records")]
    assert [r.name for r in old] == [r.name for r in rows]
    assert all(math.isnan(r.threshold) and r.status == "trained" and r.inherited_from == ""
               for r in old)


def test_summaries_read_back_what_they_wrote(tmp_path: Path) -> None:
    history = [row(0, 0.5), row(1, 0.25), row(2, 0.75, ("robot-0", "robot-1"), accepted=False)]
    summary = RunSummary.of(history, method="E+L", robot_budget=3, wall_seconds=2.0)
    assert summary.best_robot == "robot-2" and summary.accept_rate == 0.0 and summary.complete
    path = write_run_summary(tmp_path / "summary.json", summary)
    assert read_run_summary(path) == summary
    assert read_run_summary(tmp_path / "none.json") is None
    assert read_train_summary(path) is None, "an evolution's summary is not a training's"
    training = TrainSummary(robot="robot-0", seed=4, fitness=0.5, env_steps=1000,
                            wall_seconds=2.0, steps_per_second=500.0,
                            timing_seconds={"physics": 1.0})
    path = write_train_summary(tmp_path / "train.json", training)
    assert read_train_summary(path) == training
    assert "success_rate" not in path.read_text(), "no evaluation, no evaluation keys"
    assert "eval_time_to_target" not in path.read_text(), "no evaluation, no evaluation keys"
    evaluated = dataclasses.replace(training, success_rate=0.0, eval_mean_return=-1.0,
                                    eval_episodes=4)
    path = write_train_summary(tmp_path / "evaluated.json", evaluated)
    assert json.loads(path.read_text())["eval_time_to_target"] is None, "none reached it"
    older = json.loads(path.read_text())
    del older["eval_time_to_target"]  # a summary written before the key existed
    (tmp_path / "older.json").write_text(json.dumps(older))
    assert read_train_summary(tmp_path / "older.json") == evaluated
    (tmp_path / "bad.json").write_text("{")
    with pytest.raises(ValueError, match="bad.json: not readable JSON"):
        read_run_summary(tmp_path / "bad.json")


def test_each_record_round_trips_through_its_json_form() -> None:
    history = [row(0, 0.5, predicted=0.4, threshold=0.1),
               row(1, 0.75, ("robot-0",), predicted=0.6, threshold=0.5, status="stopped-early",
                   inherited_from="robot-0")]
    records: list[tuple[object, dict[str, object], list[str]]] = [
        (r, r.record(), list(HISTORY_COLUMNS)) for r in history]
    summary = RunSummary.of(history, method="E+L", robot_budget=3, wall_seconds=2.0)
    records.append((summary, summary.record(), [f.name for f in dataclasses.fields(RunSummary)]))
    training = TrainSummary(robot="robot-0", seed=4, fitness=0.5, env_steps=1000,
                            learner="ppo", arena="reach", episodes=3, wall_seconds=2.0,
                            steps_per_second=500.0, timing_seconds={"physics": 1.0})
    evaluated = dataclasses.replace(training, success_rate=0.5, eval_mean_return=1.5,
                                    eval_episodes=4, eval_time_to_target=2.25,
                                    stochastic_success_rate=0.75, stochastic_mean_return=1.25,
                                    kept_at=800)
    keys = [f.name for f in dataclasses.fields(TrainSummary)]
    unevaluated = [k for k in keys if k not in (*TrainSummary.EVALUATION, "kept_at")]
    records += [(training, training.record(), unevaluated),
                (evaluated, evaluated.record(), keys)]
    for record, form, keys in records:
        assert list(form) == keys, f"{type(record).__name__}'s JSON form names {list(form)}"
        back = json.loads(json.dumps(form))
        if isinstance(record, HistoryRow):
            assert back["parents"] == ";".join(record.parents)
            assert HistoryRow.from_record(back) == record
        else:
            assert type(record)(**back) == record, f"{type(record).__name__} does not read back"


def test_a_retraining_s_records_read_back(tmp_path: Path) -> None:
    settings = RetrainSettings(("+exp=retrain",), 128, 2, 0, True, ("robot-00000001",),
                               "learner: {}\n", first_seed=3, evaluate=True, confirm=2,
                               labels=("snake",))
    write_retrain_settings(tmp_path / "settings.json", settings)
    assert read_retrain_settings(tmp_path / "settings.json") == settings
    older = {k: v for k, v in settings.record().items()
             if k not in ("first_seed", "evaluate", "confirm", "labels")}
    (tmp_path / "older.json").write_text(json.dumps(older))
    assert read_retrain_settings(tmp_path / "older.json") == dataclasses.replace(
        settings, first_seed=None, evaluate=False, confirm=0, labels=()), "defaults"
    row = TrainingRow("a_s0", "robot-00000001", "seed", "ppo", 0, 7, 128, -0.5, -0.4, 3, 128,
                      1.5, 1.2, robot="snake", origin="designed", success_rate=0.5)
    assert list(row.record()) == list(TRAINING_COLUMNS)
    write_trainings(tmp_path / "trainings.csv", pd.DataFrame([row.record()]))
    back = read_trainings(tmp_path / "trainings.csv")
    pd.testing.assert_frame_equal(back.astype(object).fillna(""),  # "" reads back as NaN
                                  pd.DataFrame([row.record()]).astype(object).fillna(""),
                                  check_dtype=False)
    trial = SweepTrial("spearman", 0.8, 20.0, 0.8, 0.7, 0.75, 3000.0, ("learner.lr=1e-3",))
    write_sweep_trial(tmp_path / "trial.json", trial)
    assert read_sweep_trial(tmp_path / "trial.json") == trial
    assert read_sweep_trial(tmp_path / "missing.json") is None


def test_the_layout_names_the_files_of_both_kinds_of_run(tmp_path: Path) -> None:
    run, train = RunLayout(tmp_path), TrainLayout(tmp_path)
    assert run.policy("a").relative_to(tmp_path).as_posix() == "evals/a.pt"
    assert run.robot("a").relative_to(tmp_path).as_posix() == "robots/a.json"
    assert [p.name for p in (run.config, run.state, run.history, run.population, run.summary,
                             run.run_mcap, run.run_rrd, run.lock)] == [
        "config.yaml", "state.json", "history.csv", "population.json", "summary.json",
        "run.mcap", "run.rrd", "lock.json"]
    assert [p.name for p in (train.robot, train.policy, train.curve, train.summary)] == [
        "robot.json", "policy.pt", "curve.csv", "summary.json"]


def test_the_state_of_a_run_made_by_an_earlier_version_loads(tmp_path: Path) -> None:
    shutil.copytree(OLD_RUN / "stopped", tmp_path / "run")
    saved = RunStore(tmp_path / "run").load()
    assert [r.birth for r in saved.history] == [0, 1, 2, 3] and not saved.pending
    assert all(math.isnan(r.threshold) for r in saved.history)
    assert len(saved.population) == 3


@pytest.mark.slow
def test_a_run_made_by_an_earlier_version_resumes_to_its_whole_history(tmp_path: Path) -> None:
    run_dir = tmp_path / "run"
    shutil.copytree(OLD_RUN / "stopped", run_dir)
    done = subprocess.run([sys.executable, str(REPO / "evo" / "main.py"), f"resume={run_dir}"],
                          cwd=tmp_path, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-3000:]
    history = read_history(run_dir / "history.csv")
    whole = read_history(OLD_RUN / "whole_history.csv")
    assert list(history.columns) == [*whole.columns, "threshold", "inherited_from",
                                     "eval_success_rate", "eval_mean_return"]
    assert history["inherited_from"].isna().all(), "no robot inherits by default"
    kept = whole[whole["birth"] < 4].drop(columns=["wall_seconds"])
    pd.testing.assert_frame_equal(history[whole.columns].drop(columns=["wall_seconds"])[:4],
                                  kept, obj="the rows the stopped run had saved")
    assert_same_history(history[whole.columns].drop(columns=["wall_seconds"]),
                        whole.drop(columns=["wall_seconds"]), OLD_RUN, population=3)
    old, new = history[history["birth"] < 4], history[history["birth"] >= 4]
    assert old["threshold"].isna().all(), "rows recorded before the column existed"
    assert new["threshold"].notna().all(), "offspring bred against a full population"
