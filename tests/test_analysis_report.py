"""The analysis end to end on a small real ablation: loading, both reports, and every
analysis command of the README as written, both notebooks included, run from the root
with a relative ``EVO_RUNS`` (``tests/readme_commands.py`` says how).

One ablation is built: the README's ``python evo/main.py +exp=ablation`` at a tiny size
(``readme_commands.TINY_EVOLUTION``), a Hydra multirun folder of the four methods
(``E+L_seed0/`` ...). Everything else reads it, the README's analysis commands included.
"""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import jupytext
import nbformat
import numpy as np
import pandas as pd
import pytest
from omegaconf import OmegaConf
from readme_commands import ANALYSIS, REPO, Command, Made, copy_of_the_root, group, run_first
from readme_commands import run as run_command

from analysis.ablation.report import ablation_tables, write_report
from analysis.early_slope.report import write_early_slope_report
from analysis.load import RunDirectoryError, launch_paths, load_runs
from analysis.stats import Resampling
from analysis.synthetic import synthetic_robots
from analysis.tables import CURVE_COLUMNS, METHODS, ROBOT_COLUMNS
from evo.record import read_curve

pytestmark = pytest.mark.slow

NOTEBOOKS = ("ablation", "early_slope")
ENV = {**os.environ, "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl")}
RESAMPLES = "200"


@pytest.fixture(scope="module")
def made(tmp_path_factory: pytest.TempPathFactory) -> Made:
    """The README's ``python evo/main.py +exp=ablation`` (tiny: ``TINY_EVOLUTION``), run
    first in a copy of the repository root."""
    return run_first(ANALYSIS, copy_of_the_root(tmp_path_factory.mktemp("root")))


@pytest.fixture(scope="module")
def ablation(made: Made) -> Path:
    """Its multirun folder: one tiny run per method, ``<method>_seed0``."""
    return made.runs["ablation"]


def run_cli(module: str, *args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", module, *args], cwd=REPO, env=ENV,
                          capture_output=True, text=True, timeout=300)


def linked_figures(markdown: str, out: Path) -> list[Path]:
    return [out / link for link in re.findall(r"!\[[^]]*\]\(([^)]+\.png)\)", markdown)]


def assert_png(path: Path) -> None:
    assert path.is_file(), f"missing figure {path}"
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n", f"{path} is not a PNG"


# ---------------------------------------------------------------- loading


def test_load_gives_one_row_per_history_row_and_the_mcap_curves(ablation: Path) -> None:
    runs = load_runs(ablation)
    robots, curves = runs.robots, runs.curves
    assert list(robots.columns[: len(ROBOT_COLUMNS)]) == list(ROBOT_COLUMNS)
    assert list(curves.columns[: len(CURVE_COLUMNS)]) == list(CURVE_COLUMNS)
    assert dict(zip(runs.runs["run"], runs.runs["method"], strict=True)) == {
        f"{m}_seed0": m for m in METHODS}
    assert (robots["seed"] == 0).all() and runs.population_size == 3
    for run in runs.runs.itertuples():
        history = pd.read_csv(ablation / run.run / "history.csv", dtype={"parents": str})
        rows = robots[robots["run"] == run.run]
        assert len(rows) == len(history) == 6, f"run {run.run}: one robots row per history row"
        assert rows["name"].tolist() == history["name"].tolist()
        assert np.allclose(rows["fitness"], history["fitness"])
        assert rows["budget"].tolist() == history["env_steps"].tolist()
        assert rows["parents"].tolist() == history["parents"].fillna("").tolist()
        assert (rows["curve_source"] == "mcap").all() and not runs.notes
        for name in rows["name"]:
            expected = read_curve(ablation / run.run / "evals" / f"{name}.mcap")
            got = curves[(curves["run"] == run.run) & (curves["name"] == name)]
            got = got.drop(columns=["run", "name"]).reset_index(drop=True)
            pd.testing.assert_frame_equal(got[list(expected.columns)], expected,
                                          check_dtype=False, obj=f"curve of {run.run}/{name}")


def test_load_keeps_each_runs_first_robots_and_says_so(ablation: Path) -> None:
    """``first``: the first N births of every run, with their curves, and a note."""
    whole = load_runs(ablation)
    runs = load_runs(ablation, first=4)
    expected = whole.robots[whole.robots["birth"] < 4].reset_index(drop=True)
    pd.testing.assert_frame_equal(runs.robots, expected)
    assert set(runs.curves["name"]) == set(expected["name"])
    assert (runs.runs["robots"] == 4).all()
    assert sum("its first 4 robots of 6" in note for note in runs.notes) == 4
    more = load_runs(ablation, first=10)
    assert len(more.robots) == len(whole.robots)
    assert any("fewer than the 10 asked for" in note for note in more.notes)


def test_load_falls_back_to_the_csv_only_when_the_mcap_is_missing(
    ablation: Path, tmp_path: Path
) -> None:
    run = shutil.copytree(ablation / "E+L_seed0", tmp_path / "E+L_seed0")
    name = pd.read_csv(run / "history.csv")["name"].iloc[-1]
    expected = read_curve(run / "evals" / f"{name}.mcap")
    (run / "evals" / f"{name}.mcap").unlink()
    with pytest.warns(UserWarning, match=rf"MCAP file is missing \({name}\)"):
        runs = load_runs(run)
    robots = runs.robots.set_index("name")
    assert robots.loc[name, "curve_source"] == "csv"
    assert (robots.drop(index=name)["curve_source"] == "mcap").all()
    assert any(name in note for note in runs.notes)
    got = runs.curves[runs.curves["name"] == name].drop(columns=["run", "name"])
    pd.testing.assert_frame_equal(got.reset_index(drop=True)[list(expected.columns)],
                                  expected, check_dtype=False)


def test_load_errors_name_the_directory_or_file(ablation: Path, tmp_path: Path) -> None:
    with pytest.raises(FileNotFoundError, match="nowhere"):
        load_runs(tmp_path / "nowhere")
    (tmp_path / "empty").mkdir()
    with pytest.raises(RunDirectoryError, match="empty.*no history.csv"):
        load_runs(tmp_path / "empty")
    run = shutil.copytree(ablation / "R+R_seed0", tmp_path / "broken")
    (run / "config.yaml").unlink()
    with pytest.raises(RunDirectoryError, match=r"broken/config.yaml"):
        load_runs(run)


# ---------------------------------------------------------------- ablation report


def test_report_cli_writes_every_table_and_figure(ablation: Path, tmp_path: Path) -> None:
    out = tmp_path / "report"
    done = run_cli("analysis.report", str(ablation), "--out", str(out), "--resamples", RESAMPLES)
    assert done.returncode == 0, done.stderr
    text = (out / "report.md").read_text()
    for method in METHODS:
        assert f"| {method} | 6 | 1 | robot |" in text, f"{method} row of the main table"
    for heading in ("## Fitness per method", "Kruskal–Wallis", "Mann–Whitney",
                    "interaction (E+L − R+L) − (E+R − R+R)", "## Beside the paper",
                    "reward scales differ"):
        assert heading in text, heading
    assert "Missing: none" in text
    stems = {p.stem for p in linked_figures(text, out)}
    expected = {"fitness_vs_RR", "best_so_far", *(f"evolution_{m}_seed0" for m in METHODS),
                *(f"curves_{m}_seed0" for m in METHODS)}
    assert stems == expected
    for path in linked_figures(text, out):
        assert_png(path)
    summary = pd.read_csv(out / "summary.csv")
    assert set(summary["method"]) == set(METHODS) and (summary["n"] == 6).all()


def test_report_lists_missing_methods_instead_of_failing(ablation: Path, tmp_path: Path) -> None:
    report = write_report(load_runs([ablation / "R+L_seed0", ablation / "E+L_seed0"]), tmp_path,
                          resampling=Resampling.seeded(0, 100))
    text = report.read_text()
    assert "Missing: R+R, E+R." in text
    assert "| R+R | 0 | 0 | missing |" in text and "| E+R | 0 | 0 | missing |" in text
    assert "Not computed: needs all four methods" in text
    assert "| R+L | E+L |" in text, "the pair that is there is still tested"
    for path in linked_figures(text, tmp_path):
        assert_png(path)
    done = run_cli("analysis.report", str(tmp_path / "nowhere"), "--out", str(tmp_path))
    assert done.returncode == 2 and "nowhere" in done.stderr


def test_with_three_seeds_per_method_runs_are_the_unit_and_per_run_means_are_tested() -> None:
    rng = np.random.default_rng(0)
    means = {"R+R": -0.8, "R+L": -0.5, "E+R": -0.7, "E+L": 0.5}
    robots = synthetic_robots(rng, means=means, seeds=(0, 1, 2), n_robots=12,
                              population_size=4)
    tables = ablation_tables(robots, Resampling(rng, n_resamples=200))
    units = tables.main.set_index("method")["unit"]
    assert units.to_dict() == {"R+R": "robot", "R+L": "robot", "E+R": "run", "E+L": "run"}
    assert tables.per_run is not None and len(tables.per_run[1]) == 6
    assert (tables.per_run[1][["n_a", "n_b"]] == 3).all().all(), "one mean per run"
    interaction = tables.interaction.set_index("contrast")["estimate"]  # type: ignore[union-attr]
    assert interaction.iloc[2] == pytest.approx(interaction.iloc[1] - interaction.iloc[0])


# ---------------------------------------------------------------- early-slope report


def test_early_slope_cli_writes_every_table_and_figure(ablation: Path, tmp_path: Path) -> None:
    out = tmp_path / "early"
    done = run_cli("analysis.early_slope", str(ablation), "--out", str(out),
                   "--resamples", RESAMPLES)
    assert done.returncode == 0, done.stderr
    text = (out / "early_slope.md").read_text()
    for method in METHODS:
        assert f"| {method} |" in text, f"{method} in the runs table"
    assert "12 robots of R+L, E+L" in text
    assert "Absent: no retrained structures" in text
    for heading in ("Rank correlation with the final fitness",
                    "Rank correlation with the mean return after the cut",
                    "Top-10 % recall", "reject the lowest quarter", "reject below the population"):
        assert heading in text, heading
    for predictor in ("value", "slope", "area", "curve", "value+slope"):
        assert f"| {predictor} |" in text
    stems = {p.stem for p in linked_figures(text, out)}
    assert stems == {"rank_fitness", "rank_after_cut", "rejection_quantile",
                     "rejection_population", "scatter"}
    for path in linked_figures(text, out):
        assert_png(path)
    metrics = pd.read_csv(out / "rank_metrics.csv")
    assert set(metrics["metric"]) == {"spearman", "kendall", "top_recall"}
    late = metrics[(metrics["fraction"] == 0.75) & (metrics["predictor"] == "value")]
    assert late["estimate"].notna().all(), "a late cut sees episodes of every robot"
    assert {"steps_saved", "fitness_lost"} <= set(pd.read_csv(out / "rejection.csv").columns)


def test_early_slope_noise_ceiling_from_retrained_structures(
    ablation: Path, tmp_path: Path
) -> None:
    robots = load_runs([ablation / "R+L_seed0", ablation / "E+L_seed0"]).robots
    rng = np.random.default_rng(0)
    for i, robot in enumerate(robots.itertuples()):  # a second training, slightly noisy
        train = tmp_path / "retrained" / f"{i}"
        train.mkdir(parents=True)
        fitness = robot.fitness + 1e-4 * rng.normal()
        (train / "summary.json").write_text(json.dumps(
            dict(robot=robot.name, seed=7, fitness=fitness, env_steps=int(robot.budget))))
    runs = load_runs([ablation / "R+L_seed0", ablation / "E+L_seed0"])
    report = write_early_slope_report(runs, tmp_path / "out",
                                      retrained=[tmp_path / "retrained"],
                                      resampling=Resampling.seeded(0, 100))
    text = report.read_text()
    assert "Spearman ρ between trainings of the same structures" in text
    assert re.search(r"\(\d+ structures, 2 seeds\)", text)


# ---------------------------------------------------------------- the README's commands


def test_the_ablation_is_a_multirun_of_the_four_methods(made: Made) -> None:
    sweep_dir = made.runs["ablation"]
    jobs = sorted(p.name for p in sweep_dir.iterdir() if p.is_dir())
    assert jobs == sorted(f"{method}_seed0" for method in METHODS), jobs
    for job in jobs:
        summary = json.loads((sweep_dir / job / "summary.json").read_text())
        assert summary["method"] == job.split("_seed")[0]
        assert summary["complete"] and summary["robots_evaluated"] == 6
        history = (sweep_dir / job / "history.csv").read_text().splitlines()
        assert len(history) == 7 and all(f",{summary['method']}," in r for r in history[1:])
        config = OmegaConf.load(sweep_dir / job / "config.yaml")
        assert config.ga.schedule.last == 1536 and config.seed == 0
    assert (sweep_dir / "multirun.yaml").is_file()


@pytest.mark.parametrize("name", NOTEBOOKS)
def test_each_notebook_is_in_step_with_its_script(name: str) -> None:
    notebook = nbformat.read(REPO / "analysis" / f"{name}.ipynb", as_version=4)
    script = jupytext.read(REPO / "analysis" / f"{name}.pct.py")
    assert [c.source for c in notebook.cells] == [c.source for c in script.cells], (
        f"analysis/{name}.ipynb and its paired .pct.py differ: run jupytext --sync")


@pytest.mark.parametrize("command", group(ANALYSIS), ids=lambda c: c.text)
def test_the_readme_command_works_as_written(made: Made, command: Command) -> None:
    run_command(command, made.root, made)


def test_relative_paths_start_where_jupyter_was_started(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("PWD", "/home/me/evo")
    assert launch_paths(f"outputs/a{os.pathsep}/data/b{os.pathsep}") == [
        Path("/home/me/evo/outputs/a"), Path("/data/b")]
    assert launch_paths("runs", launched_from="/srv") == [Path("/srv/runs")]
    assert launch_paths("") == []
