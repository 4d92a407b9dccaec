"""``python -m analysis <study> ARGS...``: every study's command line, by the study's name.

``python -m analysis`` alone lists the studies. Each name runs the study's own command
line with the arguments that follow, so ``python -m analysis ablation RUNS --out DIR``
is ``python -m analysis.report RUNS --out DIR``; the module commands of each study keep
working as they are.
"""

from __future__ import annotations

import importlib
import sys
from collections.abc import Callable, Sequence

STUDIES: dict[str, tuple[str, str]] = {
    "ablation": ("analysis.ablation.report",
                 "the ablation report (python -m analysis.report)"),
    "power": ("analysis.ablation.power",
              "the GA seeds a run-level test of the ablation needs (python -m analysis.power)"),
    "early_slope": ("analysis.early_slope.report",
                    "does the start of a learning curve predict fitness? "
                    "(python -m analysis.early_slope)"),
    "equal_cost": ("analysis.equal_cost.early_rejection",
                   "early rejection at equal cost (python -m analysis.equal_cost)"),
    "inheritance": ("analysis.equal_cost.inheritance",
                    "policy inheritance at equal cost (python -m analysis.inheritance)"),
    "designer": ("analysis.designer",
                 "evolution against the designer (python -m analysis.designer)"),
    "noise_ceiling": ("analysis.noise_ceiling",
                      "fitness: structure or seed? (python -m analysis.noise_ceiling)"),
    "noise_study": ("analysis.noise_study",
                    "the noise ceiling across settings (python -m analysis.noise_study)"),
    "tasks": ("analysis.tasks",
              "every body on every task: the cross-task matrix (python -m analysis.tasks)"),
    "noise_sweep": ("analysis.noise_sweep",
                    "the learner's settings against the noise (python -m analysis.noise_sweep)"),
}
"""Study name → the module whose ``main(argv)`` is its command line, and what it does."""


def usage() -> str:
    """The list of studies, one a line."""
    width = max(map(len, STUDIES))
    lines = [f"  {name:<{width}}  {what}" for name, (_, what) in STUDIES.items()]
    return "usage: python -m analysis <study> ARGS...\n\nstudies:\n" + "\n".join(lines)


def command(study: str) -> Callable[[Sequence[str]], int]:
    """The command line of ``study``, its module imported only now (a study's imports
    are its own)."""
    main: Callable[[Sequence[str]], int] = importlib.import_module(STUDIES[study][0]).main
    return main


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m analysis <study> ARGS...``; exit as the study's command does, 0 with
    ``--help`` alone, 2 for no or an unknown study."""
    args = list(sys.argv[1:] if argv is None else argv)
    if args[:1] in (["-h"], ["--help"]):
        print(usage())
        return 0
    if not args or args[0] not in STUDIES:
        given = f"unknown study {args[0]!r}" if args else "no study given"
        print(f"error: {given}\n{usage()}", file=sys.stderr)
        return 2
    return command(args[0])(args[1:])


if __name__ == "__main__":
    sys.exit(main())
