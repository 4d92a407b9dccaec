"""Console progress of an evolution run and its final summary (rich)."""

from __future__ import annotations

import math
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from rich.console import Console
from rich.progress import (
    BarColumn,
    Progress,
    TaskID,
    TextColumn,
    TimeElapsedColumn,
    TimeRemainingColumn,
)
from rich.table import Table


class EvolutionProgress:
    """Robots done / budget, best and mean fitness of the population, accept rate, ETA."""

    def __init__(self, progress: Progress, task: TaskID) -> None:
        self.progress, self.task = progress, task
        self.offspring = self.accepted = 0

    def __call__(self, row: dict[str, Any]) -> None:
        if row["parents"]:
            self.offspring += 1
            self.accepted += int(row["accepted"])
        best, mean = row["population_best"], row["population_mean"]
        rate = f"{self.accepted / self.offspring:.0%}" if self.offspring else "-"
        status = f"best {best:+.3f} mean {mean:+.3f} accept {rate}" if math.isfinite(best) else ""
        if row["error"]:
            status += f" [red]{row['name']} failed[/red]"
        self.progress.update(self.task, advance=1, status=status)

    def resumed(self, history: list[dict[str, Any]]) -> None:
        """Count the robots a previous session already evaluated."""
        for row in history:
            self(row)


@contextmanager
def evolution_progress(budget: int, method: str) -> Iterator[EvolutionProgress]:
    progress = Progress(
        TextColumn(f"[bold]{method}"),
        BarColumn(),
        TextColumn("{task.completed}/{task.total} robots"),
        TextColumn("{task.fields[status]}"),
        TimeElapsedColumn(),
        TimeRemainingColumn(),
    )
    with progress:
        yield EvolutionProgress(progress, progress.add_task(method, total=budget, status=""))


def print_summary(summary: dict[str, Any], run_dir: Path, console: Console | None = None) -> None:
    """The final table: best robot, fitness, speed, and where the files are."""
    console = console or Console()
    table = Table(title=f"evolution {summary['method']}", show_header=False)
    for key in (
        "robots_evaluated",
        "failed",
        "best_robot",
        "best_fitness",
        "best_initial_fitness",
        "accept_rate",
        "env_steps",
        "wall_seconds",
        "steps_per_second",
    ):
        value = summary[key]
        text = f"{value:,.4g}" if isinstance(value, float) else str(value)
        table.add_row(key.replace("_", " "), text)
    console.print(table)
    for line in where_to_look(summary, run_dir):
        console.print(line, soft_wrap=True, highlight=False)


def where_to_look(summary: dict[str, Any], run_dir: Path) -> list[str]:
    """Where the best robot's files are and the commands that open them."""
    lines = [f"history: {run_dir / 'history.csv'}   summary: {run_dir / 'summary.json'}"]
    best = summary["best_robot"]
    if not best:
        return lines
    robot = run_dir / "robots" / f"{best}.json"
    evals = run_dir / "evals"
    lines += [f"best robot: {robot}", f"its policy: {evals / f'{best}.pt'}"]
    recordings = [evals / f"{best}{ext}" for ext in (".rrd", ".mcap")]
    lines += [f"recording: {path}" for path in recordings if path.is_file()]
    lines += [
        "open them:",
        f"  python -m evo.robot info {robot}  # modules, sizes",
        f"  python -m evo.replay {run_dir} {best} --video {run_dir / f'{best}.mp4'}",
        f"  python evo/main.py +exp=evaluate robot={robot} checkpoint={evals / f'{best}.pt'}",
    ]
    if recordings[0].is_file():
        lines.append(f"  rerun {recordings[0]}  # 3D episodes and learning curve")
    if recordings[1].is_file():
        lines.append(f"  Foxglove: open {recordings[1]}")
    return lines
