"""The fitness-fidelity study (SPEC §10): which budget and settings make fitness a signal?

Runs :mod:`analysis.noise_ceiling` on one sample of random robots under a grid of
named settings and budgets, one output folder per cell, and gathers every finished
cell into one table (budget × settings → Spearman ρ, ICC, top-quarter agreement, the
share of structures that beat the random learner, env steps/s), for every fitness
estimator:

    python -m analysis.noise_study run --out runs/noise --settings paper t400 \\
        --budgets 30000 60000 [--random 24 --seed 0 --seeds 2] [-- overrides...]
    python -m analysis.noise_study table runs/noise --out docs/results/fitness_noise.md

``run`` is resumable like the tool itself: the same command continues unfinished
cells and reuses finished trainings. Each cell's folder is
``<out>/<settings>_<budget // 1000>k``; its ``summary.json`` keeps the exact command.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path

import pandas as pd

from analysis import noise_ceiling as nc
from analysis.markdown import fmt_ci, markdown_table
from analysis.plots import plot_noise_study

SETTINGS: dict[str, tuple[str, ...]] = {
    # The paper's learner (ML-Agents' 12 areas, 128-step rollouts) and episodes of
    # 1,000 control steps (50 s): what +exp=paper_clean and ablation_paper use.
    "paper": ("learner.num_envs=12", "learner.rollout_steps=128", "learner.minibatch_size=512",
              "learner.lr=3e-4"),
    # The learner defaults (conf/learner/ppo.yaml): 32 arenas x 64 steps.
    "default": (),
    # Episodes of 400 control steps: 20 s, the paper's 1,000 Unity steps of 0.02 s.
    "t400": ("env.task.t_max=400",),
    # Episodes of 200 control steps (10 s).
    "t200": ("env.task.t_max=200",),
    # 20 s episodes, 12 arenas x 128 as in the paper.
    "paper_t400": ("learner.num_envs=12", "learner.rollout_steps=128",
                   "learner.minibatch_size=512", "learner.lr=3e-4", "env.task.t_max=400"),
    # 20 s episodes, a faster learner: Adam 1e-3, minibatches of 1,024.
    "t400_lr1e-3": ("env.task.t_max=400", "learner.lr=1e-3", "learner.minibatch_size=1024"),
    # 20 s episodes, 64 arenas x 32 steps, Adam 1e-3, minibatches of 1,024.
    "t400_64x32": ("env.task.t_max=400", "learner.num_envs=64", "learner.rollout_steps=32",
                   "learner.lr=1e-3", "learner.minibatch_size=1024"),
    # 20 s episodes, 8 epochs per batch.
    "t400_ep8": ("env.task.t_max=400", "learner.epochs=8"),
    # The learner defaults' 32 arenas x 64 steps and 50 s episodes, a faster learner:
    # Adam 1e-3, minibatches of 1,024.
    "lr1e-3": ("learner.lr=1e-3", "learner.minibatch_size=1024"),
    # The learner defaults with 8 epochs per batch (twice the gradient steps).
    "ep8": ("learner.epochs=8",),
    # The learner defaults with a slower learner: Adam 1e-4.
    "lr1e-4": ("learner.lr=1e-4",),
    # The noise sweep's best (trial 2 of +exp=noise_sweep, docs/results/noise_sweep/), what
    # +exp=ablation uses: GAE lambda 0.8, minibatches of 1,024, no entropy bonus, initial
    # log std -1, reward scaling, 6.25 ms x 8 physics.
    "sweep": ("learner.lmbda=0.8", "learner.minibatch_size=1024", "learner.entropy_coeff=0",
              "learner.init_log_std=-1", "learner.reward_scaling=true",
              "physics_step=dt6p25ms_x8"),
}
"""Named settings: config overrides on top of the defaults (``record=off`` is added)."""


def cell_folder(out: Path, settings: str, budget: int) -> Path:
    """The output folder of one cell of the grid."""
    return out / f"{settings}_{budget // 1000}k"


def run(out: Path, names: Sequence[str], budgets: Sequence[int], *, random: int, seed: int,
        seeds: int, extra: Sequence[str]) -> int:
    """Run the noise ceiling of every (settings, budget) cell, in the order given."""
    unknown = [n for n in names if n not in SETTINGS]
    if unknown:
        print(f"error: --settings: unknown {', '.join(unknown)}; expected some of "
              f"{', '.join(SETTINGS)}", file=sys.stderr)
        return 2
    status = 0
    for budget in budgets:
        for name in names:
            argv = ["--random", str(random), "--seed", str(seed), "--seeds", str(seeds),
                    "--budget", str(budget), "--out", str(cell_folder(out, name, budget)),
                    "record=off", *SETTINGS[name], *extra]
            print(f"== {name} at {budget:,} env steps", flush=True)
            status = max(status, nc.main(argv))
    return status


def study_table(folders: Sequence[Path]) -> pd.DataFrame:
    """One row per finished cell and estimator: settings, budget, metrics, speed."""
    rows = []
    for folder in folders:
        summary = nc.read_summary(folder)
        if summary is None:
            continue
        settings = summary["settings"]
        for estimator, m in summary["metrics"].items():
            rows.append(dict(
                settings=folder.name.rsplit("_", 1)[0], budget=settings["budget"],
                estimator=estimator, structures=int(m["n_structures"]),
                **{metric: fmt_ci(m[metric], m[f"{metric}_low"], m[f"{metric}_high"], digits=2)
                   for metric in ("spearman", "icc", "top_quarter", "clears_baseline")},
                steps_per_second=summary["steps_per_second"], command=summary["command"],
                **{f"{metric}_{part}": m[f"{metric}{end}"] for metric in ("spearman", "icc")
                   for part, end in (("value", ""), ("low", "_low"), ("high", "_high"))}))
    table = pd.DataFrame(rows)
    if table.empty:
        return table
    return table.sort_values(["estimator", "budget", "settings"]).reset_index(drop=True)


def table_markdown(table: pd.DataFrame, notes: str = "", figure: str = "") -> str:
    """The study's Markdown: ``notes`` (what the table says, written by hand), one table
    per estimator, ``figure`` (a PNG beside the file) and every cell's command."""
    parts = ["# Fitness fidelity: budget × settings → noise ceiling\n\n",
             "Each cell trains the same random robots twice with independent seeds (and "
             "once with the random learner) through `python -m analysis.noise_ceiling`; "
             "bootstrap 95 % CIs over structures. Settings:\n\n"]
    for name in pd.unique(table["settings"]):
        overrides = " ".join(SETTINGS.get(name, ())) or "(learner and env defaults)"
        parts.append(f"- `{name}`: `{overrides}`\n")
    if notes:
        parts += ["\n", notes.strip(), "\n"]
    if figure:
        parts.append(f"\n![Spearman rho and ICC against budget (Eq. 8)]({figure})\n")
    for estimator, rows in table.groupby("estimator", sort=False):
        parts += [f"\n## {estimator}: {nc.ESTIMATORS.get(str(estimator), '')}\n\n",
                  markdown_table(rows[["budget", "settings", "structures", "spearman", "icc",
                                       "top_quarter", "clears_baseline", "steps_per_second"]],
                                 digits=0)]
    parts.append("\n## Commands\n\n")
    commands = table.drop_duplicates(["settings", "budget"])
    parts += [f"- `{c}`\n" for c in commands["command"]]
    return "".join(parts)


def main(argv: Sequence[str] | None = None) -> int:
    cli = argparse.ArgumentParser(prog="python -m analysis.noise_study",
                                  description=__doc__.splitlines()[0])
    verbs = cli.add_subparsers(dest="verb", required=True)
    go = verbs.add_parser("run", help="run the grid's noise ceilings")
    go.add_argument("--out", type=Path, required=True)
    go.add_argument("--settings", nargs="+", required=True, help=", ".join(SETTINGS))
    go.add_argument("--budgets", nargs="+", type=int, required=True)
    go.add_argument("--random", type=int, default=24)
    go.add_argument("--seed", type=int, default=0)
    go.add_argument("--seeds", type=int, default=2)
    go.add_argument("extra", nargs="*", help="overrides added to every cell (after --)")
    tab = verbs.add_parser("table", help="gather finished cells into one Markdown table")
    tab.add_argument("folders", nargs="+", type=Path,
                     help="cell folders, or folders holding them")
    tab.add_argument("--out", type=Path, required=True, help="Markdown file to write")
    tab.add_argument("--notes", type=Path, default=None,
                     help="Markdown put after the settings (what the table shows)")
    args = cli.parse_args(argv)
    if args.verb == "run":
        return run(args.out, args.settings, args.budgets, random=args.random, seed=args.seed,
                   seeds=args.seeds, extra=args.extra)
    cells = sorted({p.parent for f in args.folders for p in f.glob("**/summary.json")})
    table = study_table(cells)
    if table.empty:
        print(f"error: no finished noise ceiling under {' '.join(map(str, args.folders))}",
              file=sys.stderr)
        return 2
    args.out.parent.mkdir(parents=True, exist_ok=True)
    figure = args.out.with_suffix(".png")
    plot_noise_study(table[table["estimator"] == "fitness"], path=figure)
    notes = args.notes.read_text(encoding="utf-8") if args.notes is not None else ""
    args.out.write_text(table_markdown(table, notes, figure.name), encoding="utf-8")
    table.drop(columns=["command"]).to_csv(args.out.with_suffix(".csv"), index=False)
    print(f"table: {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
