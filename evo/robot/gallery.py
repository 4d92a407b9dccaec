"""A gallery of robots: their files, a table of their sizes and a contact sheet."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from rich.console import Console
from rich.table import Table

from evo.robot.builder import PhysicsParams
from evo.robot.io import save_robot
from evo.robot.tree import ModuleType, Robot


def size_table(robots: Sequence[Robot]) -> Table:
    """One row per robot: name, module counts, m, n, depth and action size (one command
    per actuator; the observation is the task's, ``evo.envs.params.observation_size``)."""
    table = Table(title=f"{len(robots)} robots")
    columns = ("name", "modules", "motors m", "pivots n", "main", "wheels", "depth", "act")
    for column in columns:
        table.add_column(column, justify="left" if column == "name" else "right", no_wrap=True)
    for robot in robots:
        table.add_row(
            robot.name,
            str(len(robot)),
            str(robot.n_motors),
            str(robot.n_pivots),
            str(robot.count(ModuleType.MAIN)),
            str(robot.count(ModuleType.WHEEL)),
            str(robot.depth),
            str(robot.n_actuators),
        )
    return table


def contact_sheet(robots: Sequence[Robot], params: PhysicsParams, path: Path,
                  titles: Sequence[str] | None = None) -> Path:
    """A grid of offscreen pictures of ``robots`` saved as ``path`` (PNG).

    Args:
        robots: The robots, four to a row.
        params: The module constants they are built with.
        path: The PNG to write.
        titles: One title per robot (a newline starts a second line); default: its
            name, motors ``m`` and pivots ``n``.

    Raises:
        RenderError: no OpenGL backend works (set ``MUJOCO_GL=egl``).
        ValueError: ``titles`` does not hold one title per robot.
    """
    from evo.robot.render import render_image

    if titles is not None and len(titles) != len(robots):
        raise ValueError(f"contact_sheet: {len(titles)} titles for {len(robots)} robots")
    if titles is None:
        titles = [f"{robot.name}  m={robot.n_motors} n={robot.n_pivots}" for robot in robots]
    images = [render_image(robot, 320, 240, params) for robot in robots]
    cols = min(4, len(images))
    rows = -(-len(images) // cols)
    fig = Figure(figsize=(3.2 * cols, 2.6 * rows))
    FigureCanvasAgg(fig)
    axes = fig.subplots(rows, cols, squeeze=False)
    for ax in axes.flat:
        ax.axis("off")
    for ax, title, image in zip(axes.flat, titles, images, strict=False):
        ax.imshow(image)
        ax.set_title(title, fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    return path


def write_gallery(
    robots: Sequence[Robot],
    out: Path,
    params: PhysicsParams,
    render: bool,
    console: Console | None = None,
) -> list[Path]:
    """Save every robot as ``out/<name>.json`` and, if ``render``, a contact sheet.

    Returns:
        The files written.
    """
    console = console or Console()
    out.mkdir(parents=True, exist_ok=True)
    written = [save_robot(robot, out / f"{robot.name}.json") for robot in robots]
    console.print(size_table(robots))
    if render:
        from evo.robot.render import RenderError

        try:
            written.append(contact_sheet(robots, params, out / "robots.png"))
        except RenderError as err:
            console.print(f"[yellow]no pictures: {err}[/yellow]")
            return written
        console.print(f"contact sheet: {written[-1]}")
    return written
