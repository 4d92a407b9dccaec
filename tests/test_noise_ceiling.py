"""The noise ceiling: its metrics on cases with a known answer, the tool on real training
(immobile structures against structures that learn), resumption, and bad input."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from analysis import noise_ceiling as nc
from analysis.noise_study import main as study_main
from analysis.stats import Resampling
from evo import fidelity
from evo.retrain import Entry, confirmation_plan, late_fitness, plan_trainings
from evo.robot import load_robot, parse_robot, save_robot
from evo.run.records import RetrainSettings

REPO = Path(__file__).resolve().parents[1]


# ---------------------------------------------------------------- metrics


def test_noise_ceiling_of_identical_and_of_independent_retraining() -> None:
    rng = np.random.default_rng(6)
    structure = np.repeat([f"robot-{i}" for i in range(40)], 3)
    train_seed = np.tile([0, 1, 2], 40)
    quality = np.repeat(rng.normal(size=40), 3)
    same = pd.DataFrame(dict(structure=structure, train_seed=train_seed, fitness=quality))
    ceiling = nc.noise_ceiling(same, Resampling(rng, n_resamples=200))
    assert ceiling["spearman"] == pytest.approx(1.0) and ceiling["n_seeds"] == 3
    assert ceiling["kendall"] == pytest.approx(1.0) and ceiling["icc"] == pytest.approx(1.0)
    assert ceiling["top_quarter"] == pytest.approx(1.0)
    assert np.isnan(ceiling["clears_baseline"]), "no baseline given"
    independent = same.assign(fitness=rng.normal(size=len(same)))
    ceiling = nc.noise_ceiling(independent, Resampling(rng, n_resamples=500))
    assert ceiling["spearman_low"] < 0 < ceiling["spearman_high"]
    assert ceiling["icc_low"] < 0 < ceiling["icc_high"] and ceiling["n_structures"] == 40
    with pytest.raises(ValueError, match="train_seed"):
        nc.noise_ceiling(same[same["train_seed"] == 0], Resampling(rng))


def test_icc_is_the_share_of_variance_between_structures() -> None:
    rng = np.random.default_rng(0)
    between, within = 2.0, 1.0  # variances: ICC = 2 / (2 + 1)
    quality = rng.normal(scale=np.sqrt(between), size=4000)
    seeds = [quality + rng.normal(scale=np.sqrt(within), size=4000) for _ in range(3)]
    assert fidelity.icc(*seeds) == pytest.approx(2 / 3, abs=0.02)
    assert fidelity.icc(quality, quality) == pytest.approx(1.0)


def test_top_quarter_and_baseline_shares_on_a_small_case() -> None:
    a = np.array([8.0, 7, 6, 5, 4, 3, 2, 1])
    b = np.array([1.0, 7, 6, 5, 4, 3, 2, 8])  # the top two: {0, 1} against {1, 7}
    assert fidelity.top_quarter(a, b) == pytest.approx(0.5)
    rows = pd.DataFrame(dict(structure=np.tile(np.arange(8), 2), train_seed=np.repeat([0, 1], 8),
                             fitness=np.concatenate([a, b])))
    baseline = pd.Series(np.full(8, 4.0), index=np.arange(8))  # means 4.5 ... 4.5, 7, 6, ...
    ceiling = nc.noise_ceiling(rows, Resampling.seeded(0, 200), baseline=baseline)
    means = (a + b) / 2
    assert ceiling["clears_baseline"] == pytest.approx(np.mean(means > 4.0))


def test_late_fitness_weights_the_episodes_of_the_second_half() -> None:
    curve = pd.DataFrame({"env_steps": [100, 200, 300, 400], "train/episodes": [5, 0, 1, 3],
                          "train/mean_return": [-1.0, np.nan, 0.5, 1.0]})
    assert late_fitness(curve, budget=400) == pytest.approx((0.5 + 3 * 1.0) / 4)
    assert np.isnan(late_fitness(curve.iloc[:2], budget=400))


def entries(*stems: str, origin: str = "designed") -> list[Entry]:
    return [Entry(stem, origin, origin, "", load_robot(REPO / "robots" / f"{stem}.json"))
            for stem in stems]


def settings(**kwargs: object) -> RetrainSettings:
    given: dict[str, object] = {"overrides": (), "budget": 128, "seeds": 2, "root_seed": 3,
                                "baseline": True, "structures": (), "config": ""} | kwargs
    return RetrainSettings(**given)  # type: ignore[arg-type]


def test_training_seeds_depend_on_the_structure_and_replicate_only() -> None:
    plan = plan_trainings(entries("snake", "inchworm"), settings())
    reordered = plan_trainings(entries("inchworm", "snake"), settings(seeds=3, baseline=False))
    seeds = {t.name: t.seed for t in plan}
    assert all(seeds[t.name] == t.seed for t in reordered if t.name in seeds)
    assert len({t.seed for t in plan if t.role == "seed"}) == 4, "independent seeds"
    snake = load_robot(REPO / "robots" / "snake.json").name
    assert seeds[f"{snake}_baseline"] == seeds[f"{snake}_s0"]
    # A structure two labels share is trained once with spawned seeds, twice by label.
    twice = [*entries("snake"), Entry("snake_again", "designed", "designed", "",
                                      load_robot(REPO / "robots" / "snake.json"))]
    assert len(plan_trainings(twice, settings(baseline=False))) == 2
    by_label = plan_trainings(twice, settings(baseline=False, first_seed=5))
    assert [(t.name, t.seed) for t in by_label] == [
        ("snake_seed5", 5), ("snake_seed6", 6), ("snake_again_seed5", 5),
        ("snake_again_seed6", 6)], "as +exp=train seed=5 and seed=6"


def test_the_confirmation_trains_the_best_of_each_origin_under_fresh_seeds() -> None:
    robots = [*entries("snake", "inchworm"), *entries("four_wheeler", origin="evolved"),
              Entry("E+L_seed1", "evolved", "E+L", "", load_robot(REPO / "robots" /
                                                                   "twisted_four_wheeler.json"))]
    rows = pd.DataFrame({
        "robot": ["snake", "snake", "inchworm", "inchworm", "four_wheeler", "four_wheeler",
                  "E+L_seed1", "E+L_seed1"],
        "origin": ["designed"] * 4 + ["evolved"] * 4, "role": "seed", "confirmation": False,
        "eval_mean_return": [0.1, 0.3, 0.5, 0.4, 0.9, 0.8, 1.0, 0.2],
        "fitness": [0.9, 0.9, 0.1, 0.1, 0.1, 0.1, 0.1, 0.1]})
    plan = confirmation_plan(robots, rows, settings(first_seed=0, evaluate=True, confirm=2))
    assert [(t.label, t.seed, t.replicate, t.confirmation) for t in plan] == [
        ("four_wheeler", 2, 2, True), ("four_wheeler", 3, 2 + 1, True),
        ("inchworm", 2, 2, True), ("inchworm", 3, 3, True)], "by mean evaluation return"
    by_fitness = confirmation_plan(robots, rows, settings(first_seed=0, confirm=2))
    assert {t.label for t in by_fitness} == {"snake", "four_wheeler"}, "no evaluation: fitness"
    # Once confirmation trainings are in the table, a resumed folder keeps its choice.
    done = pd.concat([rows, pd.DataFrame({"robot": ["snake"], "origin": ["designed"],
                                          "role": ["seed"], "confirmation": [True],
                                          "eval_mean_return": [0.0], "fitness": [0.0]})])
    kept = confirmation_plan(robots, done, settings(first_seed=0, evaluate=True, confirm=2))
    assert {t.label for t in kept} == {"snake"}
    assert confirmation_plan(robots, rows, settings(first_seed=0, evaluate=True)) == []


# ---------------------------------------------------------------- the tool, for real

WHEEL = {"type": "wheel"}
MOTOR = {"type": "motor", "children": [{"face": 2, "module": WHEEL}, {"face": 3, "module": WHEEL}]}
LIFTED = {"type": "main", "children": [{"face": 4, "module": MOTOR}]}  # wheels in the air
MOVERS = {
    "twisted_four_wheeler": None,  # robots/twisted_four_wheeler.json
    "two_motors": [{"face": 0, "module": MOTOR}, {"face": 1, "module": MOTOR}],
}
IMMOBILE = {
    "immobile_one": [{"face": 0, "module": LIFTED}],
    "immobile_two": [{"face": 0, "module": LIFTED}, {"face": 1, "module": LIFTED}],
}
# An easy task and a fast learner, so that learning shows within a test-sized budget.
OVERRIDES = ["learner.num_envs=16", "learner.rollout_steps=32", "learner.lr=1e-3",
             "env.task.t_max=100", "env.task.target_min=0.3", "env.task.target_max=0.6",
             "env.task.success_radius=0.15", "record=off", "executor.workers=2"]
BUDGET = 20_480


def robots_folder(folder: Path) -> dict[str, str]:
    """Two robots that drive and two whose motors spin their wheels in the air;
    returns file stem -> structure name."""
    folder.mkdir(parents=True)
    shutil.copy(REPO / "robots" / "twisted_four_wheeler.json", folder / "twisted_four_wheeler.json")
    for stem, children in {**IMMOBILE, "two_motors": MOVERS["two_motors"]}.items():
        robot = parse_robot({"format": "evo.robot/1",
                             "root": {"type": "brain", "children": children}}, source=stem)
        save_robot(robot, folder / f"{stem}.json")
    return {path.stem: load_robot(path).name for path in folder.glob("*.json")}


@pytest.fixture(scope="module")
def ceiling_run(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict[str, str]]:
    root = tmp_path_factory.mktemp("noise")
    names = robots_folder(root / "robots")
    out = root / "ceiling"
    argv = ["--robots", str(root / "robots"), "--out", str(out), "--budget", str(BUDGET),
            "--resamples", "200", *OVERRIDES]
    assert nc.main(argv) == 0
    return out, names


@pytest.mark.long  # trains 12 robots (ceiling_run); the sweep's trials run the same code
def test_immobile_structures_rank_last_and_seeds_agree(
    ceiling_run: tuple[Path, dict[str, str]],
) -> None:
    out, names = ceiling_run
    trainings = pd.read_csv(out / nc.TRAININGS)
    assert len(trainings) == 4 * 2 + 4, "two seeds and one baseline per structure"
    assert (trainings["env_steps"] >= BUDGET).all()
    seeds = trainings[trainings["role"] == "seed"].pivot_table(
        index="structure", columns="replicate", values="fitness")
    immobile = [names[s] for s in IMMOBILE]
    movers = [n for n in seeds.index if n not in immobile]
    for replicate in seeds.columns:
        worst_mover = seeds.loc[movers, replicate].min()
        assert (seeds.loc[immobile, replicate] < worst_mover).all(), seeds
    assert seeds.loc[immobile].to_numpy() == pytest.approx(-1.0, abs=1e-4), (
        "a robot that cannot move earns the time penalty alone")
    summary = json.loads((out / "summary.json").read_text())
    metrics = summary["metrics"]["fitness"]
    # The report's ICC is the one of the table's two seeds; how high it is depends on how
    # alike PPO's two trainings of a mover turn out (seed to seed, and across library
    # versions), so the test asks only that structure explains part of the variance,
    # which the immobile structures' -1 against the movers guarantees.
    by_seed = [seeds[replicate].to_numpy() for replicate in seeds.columns]
    assert metrics["icc"] == pytest.approx(fidelity.icc(*by_seed)), metrics
    assert metrics["icc"] > 0 and metrics["spearman"] > 0, metrics
    assert metrics["clears_baseline"] == pytest.approx(0.5), "the movers learn, no one else"
    assert set(movers) == {names[s] for s in MOVERS}
    assert summary["env_steps"] == int(trainings["env_steps"].sum())
    # A training's cost is its process's CPU time: spent, and within its wall time on
    # the one thread a worker trains with (a little slack for the clocks' resolution).
    assert (trainings["cpu_seconds"] > 0).all(), trainings
    assert (trainings["cpu_seconds"] <= trainings["wall_seconds"] * 1.05 + 0.05).all(), trainings
    assert (out / "noise_ceiling.png").stat().st_size > 0
    text = (out / nc.REPORT).read_text()
    assert "| fitness |" in text and "| fitness_late |" in text


@pytest.mark.long  # trains 12 robots (ceiling_run); the sweep's trials run the same code
def test_the_same_seeds_give_the_same_numbers_and_finished_trainings_are_reused(
    ceiling_run: tuple[Path, dict[str, str]], tmp_path: Path,
) -> None:
    out, _ = ceiling_run
    first = pd.read_csv(out / nc.TRAININGS).set_index("name")
    # One training redone from scratch in another folder gives the same fitness.
    copy = tmp_path / "copy"
    shutil.copytree(out, copy)
    table = pd.read_csv(copy / nc.TRAININGS)
    redo = table["name"].iloc[0]
    table.iloc[1:].to_csv(copy / nc.TRAININGS, index=False)
    robots = out.parent / "robots"
    argv = ["--robots", str(robots), "--out", str(copy), "--budget", str(BUDGET),
            "--resamples", "200", *OVERRIDES]
    assert nc.main(argv) == 0
    again = pd.read_csv(copy / nc.TRAININGS).set_index("name")
    assert again.loc[redo, "fitness"] == pytest.approx(first.loc[redo, "fitness"], abs=1e-9)
    for name in first.index.drop(redo):  # reused, not retrained
        assert again.loc[name, "wall_seconds"] == first.loc[name, "wall_seconds"]
    summary = json.loads((copy / "summary.json").read_text())
    assert summary["metrics"] == json.loads((out / "summary.json").read_text())["metrics"]


@pytest.mark.long  # trains 12 robots (ceiling_run); the sweep's trials run the same code
def test_a_folder_of_other_settings_is_refused(
    ceiling_run: tuple[Path, dict[str, str]], capsys: pytest.CaptureFixture[str],
) -> None:
    out, _ = ceiling_run
    argv = ["--robots", str(out.parent / "robots"), "--out", str(out), "--budget", "4096",
            *OVERRIDES]
    assert nc.main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "budget" in err and str(out) in err


@pytest.mark.long  # trains 12 robots (ceiling_run); the sweep's trials run the same code
def test_the_early_slope_study_reads_a_noise_ceiling_folder(
    ceiling_run: tuple[Path, dict[str, str]],
) -> None:
    from analysis.load import load_retrained
    from analysis.stats import Resampling

    out, _ = ceiling_run
    retrained = load_retrained([out])
    assert len(retrained) == 8 and sorted(retrained["train_seed"].unique()) == [0, 1]
    assert set(retrained["structure"]) == set(pd.read_csv(out / nc.TRAININGS)["structure"])
    # The same numbers as the tool's own table: every structure under both replicates.
    ceiling = nc.noise_ceiling(retrained, Resampling.seeded(0, 200))
    written = pd.read_csv(out / "noise_ceiling.csv").set_index("estimator").loc["fitness"]
    assert ceiling["n_structures"] == 4 and ceiling["n_seeds"] == 2
    assert ceiling["spearman"] == pytest.approx(written["spearman"])
    assert ceiling["icc"] == pytest.approx(written["icc"])


@pytest.mark.long  # trains 12 robots (ceiling_run); the sweep's trials run the same code
def test_the_study_table_gathers_cells(
    ceiling_run: tuple[Path, dict[str, str]], tmp_path: Path,
) -> None:
    out, _ = ceiling_run
    assert study_main(["table", str(out.parent), "--out", str(tmp_path / "t.md")]) == 0
    text = (tmp_path / "t.md").read_text()
    assert f"| {BUDGET} |" in text and "python -m analysis.noise_ceiling" in text
    assert (tmp_path / "t.png").stat().st_size > 0 and "(t.png)" in text
    table = pd.read_csv(tmp_path / "t.csv")
    assert set(table["estimator"]) == set(nc.ESTIMATORS)


# ---------------------------------------------------------------- bad input


@pytest.mark.parametrize(("args", "message"), [
    # One of each kind the alias passes on (each starts the evo task): an argument, a
    # robot folder, a config key; test_retrain checks the rest of the retrain task's.
    (["--random", "5", "--seeds", "1"], "--seeds: expected at least 2"),
    (["--robots", "{bad}"], "not_a_robot.json"),
    (["--random", "3", "learner.teleport=1"], "teleport"),
])
def test_bad_input_gets_one_clear_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], args: list[str], message: str,
) -> None:
    (tmp_path / "empty").mkdir()
    (tmp_path / "bad").mkdir()
    shutil.copy(REPO / "robots" / "snake.json", tmp_path / "bad" / "snake.json")
    (tmp_path / "bad" / "not_a_robot.json").write_text('{"format": "evo.robot/1"}')
    folders = {k: str(tmp_path / k) for k in ("empty", "bad", "missing")}
    argv = [a.format(**folders) for a in args] + ["--out", str(tmp_path / "out")]
    assert nc.main(argv) == 2
    err = capsys.readouterr().err.strip()
    first = err.splitlines()[0]  # an invalid robot's file lists its violations below
    assert first.startswith("error:") and message in first and "Traceback" not in err, err
    assert not (tmp_path / "out" / nc.TRAININGS).exists(), "nothing trained"
