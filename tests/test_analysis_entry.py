"""``python -m analysis <study>`` and the module commands users type run the same code."""

from __future__ import annotations

import importlib
import os
import subprocess
import sys
from pathlib import Path

import pytest

from analysis.__main__ import STUDIES, command, main

REPO = Path(__file__).resolve().parents[1]
MODULE_COMMANDS = {
    "analysis.report": "ablation",
    "analysis.power": "power",
    "analysis.ablation.__main__": "ablation",
    "analysis.early_slope.__main__": "early_slope",
    "analysis.equal_cost.__main__": "equal_cost",
    "analysis.inheritance": "inheritance",
}
"""What ``python -m <module>`` runs for the studies this package groups, and the study's
name in ``python -m analysis <study>``."""


@pytest.mark.parametrize("module", sorted(MODULE_COMMANDS))
def test_a_module_command_runs_its_studys_command_line(module: str) -> None:
    assert importlib.import_module(module).main is command(MODULE_COMMANDS[module])


def test_every_study_names_a_command_line() -> None:
    for study in STUDIES:
        assert callable(command(study)), study


def test_no_or_an_unknown_study_lists_the_studies(capsys: pytest.CaptureFixture[str]) -> None:
    assert main([]) == 2
    assert "no study given" in capsys.readouterr().err
    assert main(["ablations"]) == 2
    err = capsys.readouterr().err
    assert "unknown study 'ablations'" in err
    assert all(f"  {study} " in err for study in STUDIES), err
    assert main(["--help"]) == 0 and "early_slope" in capsys.readouterr().out


@pytest.mark.parametrize("args", [("analysis", "equal_cost"), ("analysis.early_slope",)])
def test_the_commands_run_from_the_shell(args: tuple[str, ...]) -> None:
    done = subprocess.run([sys.executable, "-m", *args, "--help"], cwd=REPO, text=True,
                          capture_output=True, timeout=120, env=dict(os.environ))
    assert done.returncode == 0, done.stderr
    study = "equal_cost" if "equal_cost" in args else "early_slope"
    assert done.stdout.startswith(f"usage: python -m analysis.{study} "), done.stdout
