"""Console progress of an evolution run and its final summary (rich)."""

from __future__ import annotations

import datetime
import math
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

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

from evo.run.layout import RunLayout
from evo.run.records import HistoryRow, RunSummary


class EvolutionProgress:
    """Robots done / budget, best and mean fitness of the population, accept rate, ETA.

    On a terminal it drives a rich progress bar; otherwise (a log file, a cluster job's
    output) it prints one plain line per evaluated robot, so a log shows the same
    progress: birth, name, fitness, accepted, the population's best, robots done and the
    ETA (from the env steps left in the schedule at this session's speed).
    """

    def __init__(self, budgets: list[int], method: str, console: Console,
                 progress: Progress | None, task: TaskID | None) -> None:
        self.budgets, self.method, self.console = budgets, method, console
        self.progress, self.task = progress, task
        self.offspring = self.accepted = 0
        self.done: set[int] = set()
        self.started, self.steps = time.perf_counter(), 0

    def __call__(self, row: HistoryRow, *, resumed: bool = False) -> None:
        self.done.add(row.birth)
        if not resumed:
            self.steps += row.env_steps
        if row.parents:
            self.offspring += 1
            self.accepted += int(row.accepted)
        best, mean = row.population_best, row.population_mean
        rate = f"{self.accepted / self.offspring:.0%}" if self.offspring else "-"
        if self.progress is not None and self.task is not None:
            status = (f"best {best:+.3f} mean {mean:+.3f} accept {rate}"
                      if math.isfinite(best) else "")
            if row.failed:
                status += f" [red]{row.name} failed[/red]"
            self.progress.update(self.task, advance=1, status=status)
        elif not resumed:
            self.console.print(self.line(row), highlight=False, soft_wrap=True)

    def line(self, row: HistoryRow) -> str:
        """The plain progress line of one evaluated robot."""
        if row.failed:
            outcome = f"failed ({row.error.strip().splitlines()[-1][:80]})"
        elif row.stopped_early:
            outcome = (f"stopped early at {row.env_steps:,} of {row.budget:,} env steps "
                       f"(predicted {row.predicted:+.4f}, fitness so far {row.fitness:+.4f})")
        else:
            outcome = f"fitness {row.fitness:+.4f} {'accepted' if row.accepted else 'rejected'}"
        return (f"{self.method} birth {row.birth} {row.name}: {outcome}; best "
                f"{row.population_best:+.4f} | {len(self.done)}/{len(self.budgets)} robots | "
                f"ETA {self.eta()}")

    def eta(self) -> str:
        """Time left: the budgets of the robots not yet evaluated at this session's speed."""
        elapsed = time.perf_counter() - self.started
        if not self.steps or elapsed <= 0:
            return "-"
        left = sum(b for i, b in enumerate(self.budgets) if i not in self.done)
        return str(datetime.timedelta(seconds=round(left / (self.steps / elapsed))))

    def resumed(self, history: list[HistoryRow]) -> None:
        """Count the robots a previous session already evaluated."""
        for row in history:
            self(row, resumed=True)
        if self.progress is None and history:
            self.console.print(f"{self.method}: resumed with {len(history)} of "
                               f"{len(self.budgets)} robots evaluated", highlight=False)


@contextmanager
def evolution_progress(budgets: list[int], method: str,
                       console: Console | None = None) -> Iterator[EvolutionProgress]:
    """Progress of a run whose robot ``i`` has training budget ``budgets[i]``."""
    console = console or Console()
    if not console.is_terminal:
        yield EvolutionProgress(budgets, method, console, None, None)
        return
    progress = Progress(
        TextColumn(f"[bold]{method}"),
        BarColumn(),
        TextColumn("{task.completed}/{task.total} robots"),
        TextColumn("{task.fields[status]}"),
        TimeElapsedColumn(),
        TimeRemainingColumn(),
        console=console,
    )
    with progress:
        task = progress.add_task(method, total=len(budgets), status="")
        yield EvolutionProgress(budgets, method, console, progress, task)


def print_summary(summary: RunSummary, run_dir: Path, console: Console | None = None) -> None:
    """The final table: best robot, fitness, speed, and where the files are."""
    console = console or Console()
    table = Table(title=f"evolution {summary.method}", show_header=False)
    for key, value in (
        ("robots_evaluated", summary.robots_evaluated),
        ("failed", summary.failed),
        ("best_robot", summary.best_robot),
        ("best_fitness", summary.best_fitness),
        ("best_initial_fitness", summary.best_initial_fitness),
        ("accept_rate", summary.accept_rate),
        ("env_steps", summary.env_steps),
        ("wall_seconds", summary.wall_seconds),
        ("steps_per_second", summary.steps_per_second),
    ):
        text = f"{value:,.4g}" if isinstance(value, float) else str(value)
        table.add_row(key.replace("_", " "), text)
    console.print(table)
    if summary.best_note:
        console.print(f"[yellow]warning:[/yellow] {summary.best_note}", soft_wrap=True)
    for line in where_to_look(summary, run_dir):
        console.print(line, soft_wrap=True, highlight=False)


def where_to_look(summary: RunSummary, run_dir: Path) -> list[str]:
    """Where the best robot's files are and the commands that open them."""
    layout = RunLayout(run_dir)
    lines = [f"history: {layout.history}   summary: {layout.summary}"]
    best = summary.best_robot
    if not best:
        return lines
    robot, policy = layout.robot(best), layout.policy(best)
    lines += [f"best robot: {robot}", f"its policy: {policy}"]
    recordings = [layout.rrd(best), layout.mcap(best)]
    lines += [f"recording: {path}" for path in recordings if path.is_file()]
    lines += [
        "open them:",
        f"  python -m evo.robot info {robot}  # modules, sizes",
        f"  python -m evo.replay {run_dir} {best} --video {run_dir / f'{best}.mp4'}",
        f"  python evo/main.py +exp=evaluate robot={robot} checkpoint={policy}",
    ]
    if recordings[0].is_file():
        lines.append(f"  rerun {recordings[0]}  # 3D episodes and learning curve")
    if recordings[1].is_file():
        lines.append(f"  Foxglove: open {recordings[1]}")
    return lines
