"""The older one-shot commands that trained and then reported (``python -m
analysis.noise_ceiling --random N --out DIR``, ``python -m analysis.designer --runs ...
--out DIR``): evo trains, analysis reads, so they start the evo task in a process of its
own and report on its folder once it ends.

:func:`run_evo` starts ``python -m evo.main <overrides>`` (the command ``python
evo/main.py <overrides>`` runs), passes its output through as it comes (each error line
through ``rename``, so that a message names the alias's option rather than the config
key it set) and waits for it. A SIGINT or SIGTERM the alias gets is passed on, so the
task stops cleanly (its state kept; the same command continues it).
"""

from __future__ import annotations

import signal
import subprocess
import sys
from collections.abc import Callable, Sequence
from pathlib import Path
from types import FrameType

START = (sys.executable, "-m", "evo.main")
"""How the alias starts evo's entry point."""
CONF_DIR = Path(__file__).resolve().parents[1] / "conf"
"""evo's config tree, which the task composes its config from."""


def config_problem(overrides: Sequence[str]) -> str | None:
    """Why Hydra cannot compose evo's config with ``overrides`` (an unknown key, group or
    option), in one line; None when it can. The task would say so too, over several
    lines; the alias says it in one before it starts anything."""
    from hydra import compose, initialize_config_dir
    from hydra.errors import HydraException

    kept = [o for o in overrides if not o.startswith("hydra.")]
    try:
        with initialize_config_dir(config_dir=str(CONF_DIR), version_base="1.3"):
            compose("config", overrides=kept)
    except HydraException as err:
        return " ".join(str(err).split())
    return None


def run_evo(overrides: Sequence[str], rename: Callable[[str], str] = str) -> int:
    """Run ``python evo/main.py <overrides>`` to its end; its exit status.

    An override Hydra cannot apply ends it at once, with one line and exit status 2.

    Args:
        overrides: The command line of the evo task.
        rename: Applied to every line the task writes to standard error before it is
            written to this process's.
    """
    # A session of its own: a Ctrl-C at the terminal reaches it once, passed on from here.
    problem = config_problem(overrides)
    if problem is not None:
        print(f"error: bad config: {problem}", file=sys.stderr)
        return 2
    process = subprocess.Popen([*START, *overrides], stderr=subprocess.PIPE, text=True,
                               bufsize=1, start_new_session=True)

    def pass_on(signum: int, frame: FrameType | None) -> None:
        process.send_signal(signum)

    handlers = {s: signal.signal(s, pass_on) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        assert process.stderr is not None
        for line in process.stderr:
            sys.stderr.write(rename(line))
            sys.stderr.flush()
        return process.wait()
    finally:
        for number, handler in handlers.items():
            signal.signal(number, handler)
