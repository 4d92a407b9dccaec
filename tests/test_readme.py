"""Every command the README shows works as written: the evolution, robot, replay and
benchmark commands, around the README's own smoke run (``tests/readme_commands.py``
says how each command is run, and which cannot be and why).

The analysis commands run in ``tests/test_analysis_report.py``, on the ablation the
analysis tests share (a second file, so ``pytest -n 2 --dist loadfile`` runs the two
halves side by side).
"""

from __future__ import annotations

import json
from pathlib import Path

import pandas as pd
import pytest
import torch
from readme_commands import (
    EXCLUDED,
    HOW,
    PLACEHOLDER,
    PLACES,
    Command,
    Made,
    copy_of_the_root,
    group,
    how,
    readme_commands,
    run,
    run_first,
)
from test_evolution import check_run_dir

from evo.components.ga import BudgetSchedule
from evo.robot import load_robot, violations

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def made(tmp_path_factory: pytest.TempPathFactory) -> Made:
    """The README's smoke run, one-robot training and its evaluation, run first in a copy
    of the root."""
    return run_first("main", copy_of_the_root(tmp_path_factory.mktemp("root")))


def test_the_smoke_run_is_a_whole_evolution(made: Made) -> None:
    run_dir = made.runs["smoke"]
    history = check_run_dir(run_dir, robot_budget=8)
    assert (history["method"] == "E+L").all()
    schedule = BudgetSchedule(initial=2048, first=2048, last=4096)
    for row in history.itertuples():
        assert row.budget == schedule.budget(row.birth, 4, 8)
        assert row.env_steps >= row.budget
    summary = json.loads((run_dir / "summary.json").read_text())
    assert summary["best_fitness"] == pytest.approx(history["fitness"].max())
    best = load_robot(run_dir / "robots" / f"{summary['best_robot']}.json")
    assert violations(best.root) == [], "the best robot is a valid robot"
    assert made.strays["smoke"] == [], "the run wrote outside its run directory"


def test_one_robot_is_trained_and_evaluated(made: Made) -> None:
    train = made.runs["train"]
    summary = json.loads((train / "summary.json").read_text())
    for key in ("fitness", "success_rate", "env_steps", "wall_seconds", "steps_per_second"):
        assert isinstance(summary[key], int | float), (key, summary)
    assert summary["env_steps"] == 1024, "the budget rounds up to whole batches of 256"
    curve = pd.read_csv(train / "curve.csv")
    assert curve["env_steps"].tolist() == [256.0, 512.0, 768.0, 1024.0]
    assert (train / ".hydra" / "config.yaml").is_file()
    assert torch.load(train / "policy.pt", weights_only=True)
    reached = summary["eval_time_to_target"]  # None when no evaluation episode reached it
    assert (reached is None) == (summary["success_rate"] == 0), summary
    evaluation = json.loads((made.runs["evaluate"] / "summary.json").read_text())
    assert evaluation["episodes"] == 2 and 0 <= evaluation["success_rate"] <= 1
    assert len(evaluation["lengths"]) == 2 and "time_to_target" in evaluation, evaluation


@pytest.mark.parametrize("command", [
    pytest.param(c, marks=pytest.mark.long) if how(c).long else c for c in group("main")
], ids=lambda c: c.text)
def test_the_readme_command_works_as_written(made: Made, command: Command) -> None:
    run(command, made.root, made)


def test_a_broken_command_fails(tmp_path: Path) -> None:
    """The check itself: an option the code does not know fails the command's test."""
    readme = tmp_path / "README.md"
    readme.write_text("```bash\npython bench/robots.py --cont 10\n```\n")
    (command,) = readme_commands(readme)
    (tmp_path / "root").mkdir()
    root = copy_of_the_root(tmp_path / "root")
    with pytest.raises(AssertionError, match="unrecognized arguments: --cont"):
        run(command, root, Made(root))


# ---------------------------------------------------------------- the tables


def test_every_table_entry_names_a_readme_command() -> None:
    commands = {c.text for c in readme_commands()}
    stale = sorted((set(EXCLUDED) | set(HOW)) - commands)
    assert not stale, f"entries of tests/readme_commands.py for no README command: {stale}"
    assert not set(EXCLUDED) & set(HOW), "a command both excluded and run"


def test_every_command_run_has_its_placeholders() -> None:
    for command in readme_commands():
        if command.text in EXCLUDED:
            continue
        fills = {placeholder for placeholder, _ in how(command).fill}
        unknown = set(PLACEHOLDER.findall(command.text)) - set(PLACES) - fills
        assert not unknown, f"{command.text}: add {sorted(unknown)} to PLACES"
    unexplained = [command for command, reason in EXCLUDED.items() if len(reason.split()) < 3]
    assert not unexplained, f"say why each is excluded: {unexplained}"
