"""Evolution against the designer (``+exp=designer``'s trainings, ``analysis.designer``'s
comparison) and the time to target of the deterministic evaluation
(``evo.learners.rollouts.evaluate_policy``).

The comparison runs end to end on a tiny budget with real PPO and MuJoCo: two hand-made
robots and the best robot of a GA run directory made from a robot file, two seeds each.
"""

from __future__ import annotations

import importlib.util
import json
import math
import os
import shutil
import subprocess
import sys
from functools import cache
from pathlib import Path

import matplotlib.colors
import matplotlib.image
import numpy as np
import pandas as pd
import pytest
import torch
from matplotlib.axes import Axes
from matplotlib.collections import PathCollection

from analysis.designer import (
    TRAINING_COLUMNS,
    comparison_table,
    folder_arena,
    main,
    mean_ci,
    method_differences,
    per_method,
    welch_difference,
    write_figures,
)
from analysis.plots import ORIGIN_COLORS, plot_designer
from evo.envs.params import EnvConfig
from evo.envs.tasks.reach import Reach
from evo.learners.rollouts import PolicyEvaluation, evaluate_policy
from evo.robot import load_robot, save_robot
from evo.robot.builder import PhysicsParams
from evo.robot.render import RenderError, render_image
from evo.run.layout import RunLayout
from evo.run.records import HistoryRow, RunSummary, write_history, write_run_summary

REPO = Path(__file__).resolve().parents[1]
FOUR_WHEELER = load_robot(REPO / "robots" / "four_wheeler.json")
TINY = ["learner.total_steps=512", "learner.num_envs=4", "learner.rollout_steps=32",
        "learner.minibatch_size=64", "learner.epochs=1", "learner.eval_episodes=3",
        "env.task.t_max=40", "env.nthread=1"]
"""Overrides of ``+exp=train`` for a training of about a second: 4 batches of 128 env
steps, 40-step episodes (so failed ones end), 3 evaluation episodes."""


class StandStill:
    """A policy whose mean action is zero: the robot does not move."""

    def mean_action(self, observation: torch.Tensor) -> torch.Tensor:
        return torch.zeros(observation.shape[0], FOUR_WHEELER.n_actuators)


def test_time_to_target_counts_the_episodes_that_reached_it() -> None:
    at_start = EnvConfig(task=Reach(t_max=40, target_min=0.0, target_max=0.0))
    reached = evaluate_policy(FOUR_WHEELER, StandStill(), physics=PhysicsParams(), env=at_start,
                              episodes=3, seed=0)  # type: ignore[arg-type]
    assert reached.successes == (True,) * 3 and reached.lengths == (1,) * 3, reached
    assert reached.time_to_target == pytest.approx(0.005 * 10), "one control step of 0.05 s"
    far = EnvConfig(task=Reach(t_max=40))
    missed = evaluate_policy(FOUR_WHEELER, StandStill(), physics=PhysicsParams(), env=far,
                             episodes=3, seed=0)  # type: ignore[arg-type]
    assert missed.success_rate == 0 and missed.lengths == (40,) * 3, missed
    assert missed.time_to_target is None, "no episode reached the target"
    assert missed.summary()["time_to_target"] is None and missed.summary()["lengths"] == [40] * 3
    coarse = evaluate_policy(FOUR_WHEELER, StandStill(), physics=PhysicsParams(timestep=0.01),
                             env=EnvConfig(task=Reach(t_max=40, frame_skip=5,
                                                           target_min=0.0, target_max=0.0)),
                             episodes=1, seed=0)  # type: ignore[arg-type]
    assert coarse.control_step == pytest.approx(0.05), "timestep x frame_skip"
    mixed = PolicyEvaluation(0.5, 0.0, (0.0, 0.0, 0.0), lengths=(10, 40, 30),
                             successes=(True, False, True), control_step=0.05)
    assert mixed.time_to_target == pytest.approx((10 + 30) / 2 * 0.05), "failures left out"


def test_intervals_hold_their_estimate_and_degenerate_cases_say_so() -> None:
    mean, low, high, n = mean_ci([1.0, 2.0, 4.0, math.nan])
    assert (mean, n) == (pytest.approx(7 / 3), 3) and low < mean < high
    assert mean_ci([0.5, 0.5]) == (0.5, 0.5, 0.5, 2), "no spread: a zero-width interval"
    assert math.isnan(mean_ci([0.5])[1]) and mean_ci([math.nan])[3] == 0
    diff, low, high = welch_difference([1.0, 1.2, 1.1], [0.0, 0.1, 0.05])
    assert diff == pytest.approx(1.1 - 0.05) and low < diff < high
    assert low > 0, "a clear difference's interval lies above 0"
    assert math.isnan(welch_difference([1.0], [0.0, 1.0])[1]), "one seed: no interval"
    # A success rate's interval stays within [0, 1], a time's above 0, a return's is free.
    rows = [dict(robot="snake", origin="designed", run="", structure="s", seed=seed,
                 fitness=0.0, success_rate=rate, eval_mean_return=ret,
                 eval_time_to_target=time, wall_seconds=1.0)
            for seed, (rate, ret, time) in enumerate([(0.2, -0.5, 1.0), (1.0, 1.0, 30.0),
                                                      (1.0, 1.1, 2.0)])]
    row = comparison_table(pd.DataFrame(rows)).iloc[0]
    assert row["success_rate_high"] == 1.0 and row["eval_time_to_target_low"] == 0.0
    assert mean_ci([0.2, 1.0, 1.0])[2] > 1 and row["eval_mean_return_low"] < -1, "unclipped"


def test_methods_are_compared_with_one_robot_per_run_as_the_unit() -> None:
    def robot(label: str, method: str, returns: list[float]) -> list[dict[str, object]]:
        origin = "designed" if method == "designed" else "evolved"
        return [dict(robot=label, origin=origin, method=method, run="", structure="s",
                     seed=seed, fitness=0.0, success_rate=1.0, eval_mean_return=value,
                     eval_time_to_target=5.0, wall_seconds=1.0)
                for seed, value in enumerate(returns)]
    trainings = pd.DataFrame([
        *robot("E+L_seed0", "E+L", [0.2, 0.4]), *robot("E+L_seed1", "E+L", [0.0, 0.2]),
        *robot("E+L+I_seed0", "E+L+I", [0.9, 1.1]), *robot("E+L+I_seed1", "E+L+I", [0.7, 0.9]),
        *robot("snake", "designed", [0.5, 0.5])])
    comparison = comparison_table(trainings)
    methods = per_method(comparison).set_index("method")
    assert methods["robots"].to_dict() == {"E+L+I": 2, "E+L": 2, "designed": 1}
    assert methods.loc["E+L", "eval_mean_return_mean"] == pytest.approx((0.3 + 0.1) / 2)
    low, high = methods.loc["E+L", ["eval_mean_return_low", "eval_mean_return_high"]]
    assert low < 0.2 < high, "an interval over the method's two robots (runs)"
    pair = method_differences(comparison).set_index("metric").loc["eval_mean_return"]
    assert pair["pair"] == "E+L+I − E+L" and pair["difference"] == pytest.approx(0.9 - 0.2)
    assert pair["low"] < pair["difference"] < pair["high"]


def test_the_figure_draws_every_robot_in_order_and_survives_missing_values() -> None:
    one_seed = dict(run="", structure="s", arena="clean", env_steps=1, fitness=0.0,
                    eval_episodes=3, wall_seconds=1.0)
    trainings = pd.DataFrame([
        dict(one_seed, robot="E+L_seed0", origin="evolved", seed=0, success_rate=1.0,
             eval_mean_return=9.0, eval_time_to_target=2.0),
        dict(one_seed, robot="E+L_seed0", origin="evolved", seed=1, success_rate=0.5,
             eval_mean_return=7.0, eval_time_to_target=3.0),
        dict(one_seed, robot="snake", origin="designed", seed=0, success_rate=0.0,
             eval_mean_return=8.0, eval_time_to_target=math.nan),  # one seed, none reached
        dict(one_seed, robot="inchworm", origin="designed", seed=0, success_rate=1.0,
             eval_mean_return=1.0, eval_time_to_target=1.0),
    ], columns=list(TRAINING_COLUMNS))
    table = comparison_table(trainings)
    fig = plot_designer(table, chosen=["E+L_seed0", "snake"])
    fig.canvas.draw()
    axes = fig.axes
    assert [ax.get_title() for ax in axes] == ["success rate", "evaluation return",
                                               "time to target (s)"]
    ticks = axes[0].get_yticklabels()
    assert [t.get_text() for t in ticks] == ["E+L_seed0", "snake", "inchworm"], "table order"
    assert [t.get_fontweight() for t in ticks] == ["bold", "bold", "normal"], "chosen marked"
    assert axes[0].get_ylim()[0] > axes[0].get_ylim()[1], "the table's first row on top"
    ttt = axes[2]
    assert [t.get_text() for t in ttt.texts] == ["not reached"], "snake never reached it"
    assert {tuple(p) for p in dots(ttt)} == {(2.5, 0.0), (1.0, 2.0)}, "no dot for snake"
    colours = {tuple(c.get_facecolor()[0][:3]) for c in axes[1].collections
               if isinstance(c, PathCollection) and len(c.get_offsets()) and
               len(c.get_facecolor())}
    assert colours == {matplotlib.colors.to_rgb(c) for c in ORIGIN_COLORS.values()}, \
        "coloured by origin"


def dots(ax: Axes) -> np.ndarray:
    """The filled points of ``ax``'s scatter collections (not the hollow rings)."""
    filled = [c.get_offsets() for c in ax.collections
              if isinstance(c, PathCollection) and len(c.get_facecolor())]
    return np.vstack([f for f in filled if len(f)])


def synthetic_run(run_dir: Path, robot_file: Path) -> str:
    """A GA run directory whose best robot is ``robot_file``'s robot: config, history,
    summary and robot file as an evolution writes them. Returns the robot's name."""
    robot = load_robot(robot_file)
    layout = RunLayout(run_dir)
    save_robot(robot, layout.robot(robot.name))
    layout.config.write_text("env:\n  name: cluttered\nseed: 0\n")
    row = HistoryRow(birth=0, name=robot.name, method="E+L", parents=(), operator="random",
                     budget=2048, seed=1, fitness=0.5, accepted=True, replaced="",
                     env_steps=2048, episodes=3, wall_seconds=1.0, error="",
                     population_best=0.5, population_mean=0.5, status="trained",
                     predicted=math.nan)
    write_history(layout.history, [row])
    write_run_summary(layout.summary, RunSummary.of([row], method="E+L", robot_budget=1,
                                                    wall_seconds=1.0))
    return robot.name


@pytest.fixture(scope="module")
def comparison(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, list[str]]:
    """A finished tiny comparison: its folder and its command line."""
    root = tmp_path_factory.mktemp("designer")
    robots = root / "hand_made"
    robots.mkdir()
    for name in ("four_wheeler", "twisted_four_wheeler"):
        shutil.copy(REPO / "robots" / f"{name}.json", robots / f"{name}.json")
    synthetic_run(root / "runs" / "E+L_seed0", REPO / "robots" / "inchworm.json")
    argv = ["--runs", str(root / "runs"), "--robots", str(robots), "--out", str(root / "out"),
            "--seeds", "2", "--confirm", "2", *TINY]  # arena: the run's config.yaml's env
    assert main(argv) == 0
    return root / "out", argv


def test_the_comparison_runs_end_to_end_on_a_tiny_budget(
        comparison: tuple[Path, list[str]]) -> None:
    out, _ = comparison
    everything = pd.read_csv(out / "trainings.csv")
    trainings = everything[~everything["confirmation"]]
    assert sorted(zip(trainings["robot"], trainings["seed"], strict=True)) == [
        (robot, seed) for robot in ("E+L_seed0", "four_wheeler", "twisted_four_wheeler")
        for seed in (0, 1)], "one row per robot and seed"
    origins = trainings.groupby("robot")["origin"].first().to_dict()
    assert origins == {"E+L_seed0": "evolved", "four_wheeler": "designed",
                       "twisted_four_wheeler": "designed"}
    assert trainings.groupby("robot")["method"].first().to_dict() == {
        "E+L_seed0": "E+L", "four_wheeler": "designed", "twisted_four_wheeler": "designed"}
    methods = pd.read_csv(out / "per_method.csv").set_index("method")
    assert methods["robots"].to_dict() == {"E+L": 1, "designed": 2}
    assert (trainings["arena"] == "cluttered").all() and (trainings["eval_episodes"] == 3).all()
    assert (trainings["env_steps"] >= 512).all() and trainings["success_rate"].between(0, 1).all()
    for row in trainings.itertuples():
        assert (out / "evals" / f"{row.robot}_seed{row.seed}.pt").is_file()
        ttt = row.eval_time_to_target
        assert math.isnan(ttt) == (row.success_rate == 0), row
        assert math.isnan(ttt) or 0 < ttt <= 40 * 0.05, "within the episode's 40 steps of 0.05 s"

    table = pd.read_csv(out / "comparison.csv")
    assert list(table["eval_mean_return_mean"]) == sorted(table["eval_mean_return_mean"],
                                                          reverse=True), "best first"
    for metric in ("success_rate", "eval_mean_return", "eval_time_to_target"):
        mean, low, high = (table[f"{metric}_{k}"] for k in ("mean", "low", "high"))
        shown = low.notna()
        assert ((low[shown] <= mean[shown] + 1e-12) & (mean[shown] <= high[shown] + 1e-12)).all()
    assert (table["success_rate_low"].dropna() >= 0).all(), "clipped to what a rate can be"
    assert (table["success_rate_high"].dropna() <= 1).all()
    per_robot = trainings.groupby("robot")["eval_mean_return"]
    means = table.set_index("robot")["eval_mean_return_mean"]
    assert np.allclose(means.sort_index(), per_robot.mean().sort_index())
    worst = table.set_index("robot")["success_rate_worst"]
    assert np.allclose(worst.sort_index(), trainings.groupby("robot")["success_rate"].min())

    duel = pd.read_csv(out / "head_to_head.csv").query("seeds == 'choice'").set_index("metric")
    best_designed = table[table["origin"] == "designed"].iloc[0]["robot"]
    evolved, designed = (trainings[trainings["robot"] == r] for r in ("E+L_seed0", best_designed))
    assert duel.loc["eval_mean_return", "difference"] == pytest.approx(
        evolved["eval_mean_return"].mean() - designed["eval_mean_return"].mean())
    report = (out / "comparison.md").read_text()
    assert "E+L_seed0 (evolved)" in report and f"{best_designed} (hand-made)" in report
    assert "**Verdict:**" in report and "Selection bias" in report

    # The confirmation: the two chosen robots again under fresh seeds 2 and 3, and the
    # verdict read from those trainings alone.
    fresh = everything[everything["confirmation"]]
    assert sorted(zip(fresh["robot"], fresh["seed"], strict=True)) == sorted(
        (r, s) for r in ("E+L_seed0", best_designed) for s in (2, 3))
    confirmed = pd.read_csv(out / "head_to_head.csv").query("seeds == 'confirmation'")
    confirmed = confirmed.set_index("metric")
    evolved, designed = (fresh[fresh["robot"] == r] for r in ("E+L_seed0", best_designed))
    difference = evolved["eval_mean_return"].mean() - designed["eval_mean_return"].mean()
    assert confirmed.loc["eval_mean_return", "difference"] == pytest.approx(difference)
    assert f"{difference:+.3f}" in report.split("**Verdict:**")[1].splitlines()[0]
    assert "fresh seeds 2, 3" in report

    # The figures: every robot's metrics, and the two chosen robots' pictures.
    figure = matplotlib.image.imread(out / "comparison.png")
    assert figure.shape[1] > 1000 and figure.shape[0] > 250 and figure.std() > 0.05, \
        figure.shape
    assert "](comparison.png)" in report
    if not can_render():
        assert "no pictures of the chosen robots" in report and "MUJOCO_GL" in report
        return
    pictures = matplotlib.image.imread(out / "chosen.png")
    assert pictures.shape[0] >= 240 and pictures.shape[1] >= 2 * 320, pictures.shape
    left, right = np.array_split(pictures[..., :3], 2, axis=1)
    assert left.std() > 0.05 and right.std() > 0.05, "a robot on each side"
    assert "](chosen.png)" in report and "no pictures" not in report


@cache
def can_render() -> bool:
    """Whether MuJoCo can render offscreen in this process (``MUJOCO_GL``)."""
    try:
        render_image(FOUR_WHEELER, 8, 8)
    except RenderError:
        return False
    return True


def test_a_comparison_without_opengl_is_done_and_says_why_it_has_no_pictures(
        comparison: tuple[Path, list[str]], tmp_path: Path) -> None:
    """The report of a folder (``python -m analysis.designer DIR``) where MuJoCo has no
    OpenGL to render with: GLFW, which needs a display, and none."""
    out, _ = comparison
    copy = tmp_path / "out"
    shutil.copytree(out, copy, ignore=shutil.ignore_patterns("*.png"))
    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")}
    done = subprocess.run([sys.executable, "-m", "analysis.designer", str(copy)], cwd=REPO,
                          env={**env, "MUJOCO_GL": "glfw", "PYTHONPATH": str(REPO)},
                          capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, "the comparison is done all the same\n" + done.stderr[-2000:]
    report = (copy / "comparison.md").read_text()
    notes = report.split("## Notes")[1]
    assert "no pictures of the chosen robots (chosen.png): no OpenGL context" in notes
    assert not (copy / "chosen.png").exists() and "](chosen.png)" not in report
    assert (copy / "comparison.png").is_file() and "](comparison.png)" in report
    assert (copy / "head_to_head.csv").is_file() and "**Verdict:**" in report
    for name in ("comparison.csv", "per_method.csv", "head_to_head.csv"):
        assert (copy / name).read_bytes() == (out / name).read_bytes(), \
            f"the folder's report again: {name} as the first time"

    # docs/pictures.py --designer draws the figures again from the folder's files.
    assert folder_arena(copy) == "cluttered"
    docs = tmp_path / "docs"
    written, notes = write_figures(copy, pd.read_csv(copy / "comparison.csv"), "cluttered",
                                   figure=docs / "designer_cluttered.png",
                                   pictures=docs / "designer_robots_cluttered.png")
    assert written[0] == docs / "designer_cluttered.png" and written[0].is_file()
    if can_render():
        assert written[1].is_file() and not notes


def test_a_rerun_skips_finished_trainings_and_refuses_another_config(
        comparison: tuple[Path, list[str]], capfd: pytest.CaptureFixture[str]) -> None:
    out, argv = comparison
    table = pd.read_csv(out / "trainings.csv")
    redo = table.index[table["name"] == "four_wheeler_seed1"]
    table.drop(redo).to_csv(out / "trainings.csv", index=False)
    policies = {p: p.stat().st_mtime_ns for p in (out / "evals").glob("*.pt")}
    capfd.readouterr()
    assert main([*argv, "--jobs", "2"]) == 0
    assert "9 of 10 trainings already done; 1 to run" in capfd.readouterr().out
    again = pd.read_csv(out / "trainings.csv")
    assert len(again) == 6 + 4, "the missing training ran again, and the confirmation's 4"
    redone = out / "evals" / "four_wheeler_seed1.pt"
    assert redone.stat().st_mtime_ns != policies[redone], "the missing training ran again"
    assert all(p.stat().st_mtime_ns == t for p, t in policies.items() if p != redone), \
        "a finished training was trained again"
    row = again.set_index("name").loc["four_wheeler_seed1"]
    first = table.set_index("name").loc["four_wheeler_seed1"]
    assert row["fitness"] == pytest.approx(first["fitness"], abs=1e-9), "the same seed"
    assert main([*argv, "learner.lr=0.5"]) == 2
    assert "other settings (config differ" in capfd.readouterr().err


def test_the_trainings_are_those_of_exp_train(comparison: tuple[Path, list[str]],
                                              tmp_path: Path) -> None:
    """``+exp=designer`` trains a robot as ``+exp=train robot=FILE seed=S`` does: the same
    fitness and the same deterministic evaluation."""
    out, _ = comparison
    cluttered = [*TINY, "env=cluttered"]  # the arena the run evolved in
    done = subprocess.run([sys.executable, str(REPO / "evo" / "main.py"), "+exp=train",
                           f"robot={out / 'robots' / 'four_wheeler.json'}", "seed=1",
                           *cluttered, f"hydra.run.dir={tmp_path / 'train'}"], cwd=tmp_path,
                          env={**os.environ, "PYTHONPATH": str(REPO), "MUJOCO_GL": "egl"},
                          capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-2000:]
    alone = json.loads((tmp_path / "train" / "summary.json").read_text())
    row = pd.read_csv(out / "trainings.csv").set_index("name").loc["four_wheeler_seed1"]
    assert row["fitness"] == pytest.approx(alone["fitness"], abs=1e-12)
    assert row["eval_mean_return"] == pytest.approx(alone["eval_mean_return"], abs=1e-12)
    assert row["success_rate"] == alone["success_rate"]


def test_reevaluating_a_folders_policies_on_the_same_episodes_gives_its_figures(
        comparison: tuple[Path, list[str]], tmp_path: Path) -> None:
    """``docs/results/deployed/reevaluate.py`` on the evaluation's own seed and episode
    count reproduces ``trainings.csv``'s figures, both ways; on more episodes it gives
    that many, and a second call keeps the first one's rows of other trainings."""
    out, _ = comparison
    script = REPO / "docs" / "results" / "deployed" / "reevaluate.py"
    spec = importlib.util.spec_from_file_location("reevaluate", script)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)  # run here: three start-ups cost more than its evaluations
    table = tmp_path / "again.csv"

    def reevaluate(*args: str) -> pd.DataFrame:
        assert module.main([f"tiny={out}", *args, "--out", str(table)]) == 0
        return pd.read_csv(table)

    again = reevaluate("--robots", "four_wheeler", "--episodes", "3", "--offset", "1")
    trainings = pd.read_csv(out / "trainings.csv")
    first = trainings[(trainings["robot"] == "four_wheeler") & ~trainings["confirmation"]]
    assert sorted(again["seed"]) == sorted(first["seed"]) == [0, 1]
    merged = again.merge(first, on="seed")
    np.testing.assert_allclose(merged["success"], merged["success_rate"])
    np.testing.assert_allclose(merged["noisy_success"], merged["stochastic_success_rate"])
    np.testing.assert_allclose(merged["eval_return"], merged["eval_mean_return"], rtol=1e-6)
    np.testing.assert_allclose(merged["noisy_return"], merged["stochastic_mean_return"],
                               rtol=1e-6)

    one = reevaluate("--robots", "twisted_four_wheeler", "--seeds", "1", "--episodes", "5")
    assert sorted(zip(one["robot"], one["seed"], strict=True)) == [
        ("four_wheeler", 0), ("four_wheeler", 1), ("twisted_four_wheeler", 1)], "the first kept"
    more = reevaluate("--robots", "twisted_four_wheeler", "--episodes", "5")
    assert set(more["robot"]) == {"four_wheeler", "twisted_four_wheeler"}
    assert more.groupby("robot")["episodes"].first().to_dict() == {
        "four_wheeler": 3, "twisted_four_wheeler": 5}
    summary = table.with_suffix(".md").read_text()
    twisted = (trainings["robot"] == "twisted_four_wheeler").sum()  # its confirmation too
    assert f"| tiny | cluttered | twisted_four_wheeler | {twisted} | 5 |" in summary, summary
