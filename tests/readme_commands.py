"""The shell commands of the README and the documentation site, and how the tests run
each one.

The pages are ``README.md`` and every page of the site's navigation (``mkdocs.yml``), in
that order (:data:`PAGES`). Every line of a fenced ``bash`` block of a page is a command
(a trailing ``\\`` joins the next line; ``# ...`` comments are dropped; a command on
several pages counts once). ``source`` and ``export`` lines set up the shell: they run
before every later command of their block, in the same shell.

The tests run each command with ``bash`` in a copy of the repository root (a folder of
links to the repository's files, so outputs land in a temporary folder, never in the
checkout), with this interpreter's virtualenv first on ``PATH``, exactly as written except
for what the tables below say:

* :data:`EXCLUDED`: commands that cannot run in a test, each with its reason;
* :data:`HOW`: per command, arguments appended to make it small, extra environment,
  what it must leave behind or print, and which test file runs it;
* :data:`PLACES`: what each placeholder (``<run dir>``, ``<date>``, ...) is filled with,
  from the runs the README's own commands made first (:attr:`How.makes_run`).

A command in none of the tables runs as written, in ``tests/test_readme.py``, with its
placeholders filled; a placeholder :data:`PLACES` does not know fails the test. A table
entry naming no README command fails ``test_every_table_entry_names_a_readme_command``.
"""

from __future__ import annotations

import fnmatch
import json
import os
import re
import subprocess
import sys
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path

import yaml

REPO = Path(__file__).resolve().parents[1]
README = REPO / "README.md"


def site_pages() -> list[Path]:
    """The pages of the site's navigation (``mkdocs.yml``'s ``nav``), in order."""
    config = yaml.safe_load((REPO / "mkdocs.yml").read_text())
    docs = REPO / config.get("docs_dir", "docs")

    def walk(node: object) -> list[Path]:
        if isinstance(node, str):
            return [docs / node]
        if isinstance(node, dict):
            return [p for value in node.values() for p in walk(value)]
        if isinstance(node, list):
            return [p for item in node for p in walk(item)]
        return []

    return walk(config["nav"])


PAGES = (README, *site_pages())
"""The pages whose commands the tests run: the README, then the site's, in order."""
SETUP = ("source ", "export ")
"""Lines that set up the shell for the lines after them in their block."""
ASSIGNMENT = re.compile(r"""[A-Za-z_]\w*=("[^"]*"|'[^']*'|\S+)""")
"""A shell variable set on a line of its own (``ROBOTS=a,b``): it sets up the shell too."""
PLACEHOLDER = re.compile(r"<[a-z][a-z ]*>|\b[A-Z]+\.\.\.|\bREV\b")
"""What a placeholder looks like: ``<run dir>``, ``RUN...``, ``REV``."""


@dataclass(frozen=True)
class Command:
    """One README command.

    Attributes:
        text: The command as written (continuations joined, the comment dropped).
        setup: The ``source``/``export`` lines before it in its block.
    """

    text: str
    setup: tuple[str, ...] = ()


def readme_commands(*pages: Path) -> list[Command]:
    """Every command of the pages' ``bash`` blocks (:data:`PAGES` when none are given),
    in order, each once (where it first appears)."""
    found: dict[str, Command] = {}
    for page in pages or PAGES:
        for block in re.findall(r"^```bash\n(.*?)^```", page.read_text(), re.S | re.M):
            setup: list[str] = []
            for text in _lines(block):
                if text.startswith(SETUP) or ASSIGNMENT.fullmatch(text):
                    setup.append(text)
                else:
                    found.setdefault(text, Command(text, tuple(setup)))
    return list(found.values())


def _lines(block: str) -> list[str]:
    """A block's commands: continuations joined, comments dropped, and a ``for`` loop's
    lines, from its ``do`` to its ``done``, joined into one command."""
    lines, loop, depth = [], "", 0
    for line in block.replace("\\\n", " ").splitlines():
        code = "" if line.lstrip().startswith("#") else line.split(" #")[0]
        text = " ".join(code.split())
        if not text:
            continue
        words = [word.strip(";") for word in text.split()]
        depth += words.count("do") - words.count("done")
        joint = "" if not loop else " " if loop.endswith("do") else "; "
        loop = f"{loop}{joint}{text}"
        if depth == 0:
            lines.append(loop)
            loop = ""
    return lines


# ---------------------------------------------------------------- the tables

EXCLUDED: dict[str, str] = {
    "make demo": "a 10-12 minute evolution; test_configs composes +exp=demo and checks "
                 "it is a small evolution, and +exp=smoke runs the same loop below",
    "make test": "the test suite itself",
    "make test-long": "the suite's long tier (pytest -m long)",
    "python evo/main.py +exp=paper_clean": "the paper's run (100 robots, about 40 minutes); "
                                           "test_configs composes and checks it",
    "python evo/main.py +exp=ablation_paper": "the ablation at the paper's budget (hours); "
                                              "test_configs composes and checks it",
    "rerun outputs/<run>/evals/<name>.rrd": "opens the rerun viewer, a GUI",
    "rerun outputs/<run>/run.rrd": "opens the rerun viewer, a GUI",
    "pip install hydra-joblib-launcher": "installs an optional plugin from the network",
    "pip install hydra-submitit-launcher": "installs an optional plugin from the network",
    "pip install hydra-ray-launcher": "installs an optional plugin from the network",
    'pip install -e ".[notebooks]"': "installs the optional notebook extra from the network",
    "python evo/main.py +exp=ablation seed=0,1 hydra/launcher=joblib hydra.launcher.n_jobs=4 "
    "executor.workers=4": "needs hydra-joblib-launcher, an optional plugin not installed",
    "python evo/main.py +exp=ablation seed=0,1,2 hydra/launcher=submitit_slurm "
    "hydra.launcher.partition=<partition> hydra.launcher.cpus_per_task=32 executor.workers=32":
        "submits Slurm jobs: needs a cluster and the submitit plugin",
    "python evo/main.py +exp=ablation hydra/launcher=ray hydra.launcher.ray.init.address=auto":
        "needs a running Ray cluster and the Ray launcher plugin",
    "python evo/main.py +exp=retrain retrain.random=24 retrain.budget=100000 "
    "hydra.run.dir=noise/ record=off": "48 trainings of 100k env steps (an hour); test_retrain "
                                       "runs the task end to end on three robots, resumed, "
                                       "and against the alias below",
    "python -m analysis.noise_ceiling noise/": "reads the folder the retrain task above makes; "
                                               "test_retrain reports on its three robots'",
    "python -m analysis.noise_ceiling --random 24 --seed 0 --seeds 2 --budget 100000 --out "
    "noise/ record=off": "cannot be shrunk as typed: its report needs episodes that end (a "
                         "budget of 32 arenas x T_max = 32k env steps per training, 6 trainings "
                         "at least: minutes), and no override can follow its options; "
                         "test_noise_ceiling runs the tool's main() on four robots",
    "python -m analysis.noise_ceiling --robots robots/ --seeds 3 --out noise3/ learner=ppo "
    "env=cluttered": "16 trainings in the cluttered arena (minutes); test_noise_ceiling runs "
                     "the tool on a folder of robots with overrides",
    "python -m analysis.noise_study run --out runs/noise --settings default paper --budgets "
    "60000 150000": "the --random noise ceiling once per setting and budget (2 x 2 cells of "
                    "72 trainings), each one the noise ceiling above",
    "python bench/kill_resume.py --kills 20":
        "runs a small evolution over 20 times (minutes; one kill still means three runs); "
        "test_evolution's SIGKILL tests drive evo/main.py with its DRIVER",
    "python bench/same_behaviour.py --before REV":
        "checks out another commit (git worktree, needs the history) and runs the "
        "evolution on both",
    "python bench/same_analysis.py --before REV":
        "checks out another commit (git worktree, needs the history) and runs the "
        "analysis commands of docs/results on both (minutes)",
    "python evo/main.py +exp=noise_sweep":
        "30 noise-ceiling trials of 32 trainings each (hours); test_noise_sweep runs the same "
        "config end to end with two tiny trials, and a rerun that continues it",
    "python evo/main.py +exp=noise_sweep hydra.sweeper.n_trials=3":
        "three trials of 32 trainings (about 20 minutes); test_noise_sweep runs two tiny ones",
    "python -m analysis.noise_sweep table runs/noise_sweep":
        "reads the study the sweep above makes; test_noise_sweep reads its tiny study's table",
    "python -m analysis.inheritance runs/inheritance --out inheritance/":
        "needs the six runs of +exp=inheritance_laptop; tests/test_analysis_inheritance.py "
        "runs the tool on small run folders",
    "python -m analysis.designer --runs outputs/ablation/<date>/E+L_seed* --out designer/ "
    "--confirm 3": "trains every run's best robot and the four hand-made ones 3 times at 150k "
                   "env steps (about an hour per arena on two cores); tests/test_designer.py "
                   "runs the tool end to end on a tiny budget, resumed",
    "python -m analysis.designer designer/": "reads the folder the command above makes; "
                                             "tests/test_designer.py reports on its tiny one's",
    "python bench/train_throughput.py --steps 150000 --quality --robots "
    "robots/twisted_four_wheeler.json --arenas cluttered --nthread 1 --seed S":
        "three 150k trainings in the cluttered arena, one per seed S (minutes each); the "
        "same options run, small, in the benchmarks page's --quality command",
    "make docs": "builds the site into site/; make test runs the same build with --strict "
                 "(tests/test_docs.py)",
    "python evo/main.py +exp=push hydra.sweep.dir=runs/tasks/push":
        "six evolutions of 60 robots in the push task (about an hour on two cores); "
        "tests/test_tasks.py runs a smoke evolution in a task and test_configs composes it",
    "python evo/main.py +exp=task_fidelity env/task=push hydra.run.dir=runs/fidelity/push":
        "48 trainings of 50k env steps (about 10 minutes on two cores); test_retrain runs "
        "the retrain task end to end",
    "python -m analysis.noise_ceiling runs/fidelity/push":
        "reads the folder the command above makes; test_retrain reports on its robots'",
    'PYTHONPATH=. python evo/main.py +exp=train robot=robots/snake.json env/task=escape '
    '"hydra.searchpath=[file://$PWD/myconf]"':
        "needs the worked example's module and YAML file written first: "
        "tests/test_tasks.py writes them from docs/tasks.md and runs the training",
    'PYTHONPATH=. python evo/main.py +exp=smoke env/task=escape '
    '"hydra.searchpath=[file://$PWD/myconf]"':
        "needs the worked example's module and YAML file written first: "
        "tests/test_tasks.py writes them from docs/tasks.md and runs the smoke evolution",
    "EVO_RUNS=outputs/ablation/<date> jupyter lab analysis/":
        "starts an interactive JupyterLab server; the kernel it starts is the one "
        "`jupyter execute` starts, run above from the same folder",
    # ---- the results pages: the experiments that made the committed data
    "docs/results/ablation/run.sh": "the ablation's runs (about 8 hours on two cores); "
                                    "test_ablation_config runs +exp=ablation's loop small",
    'ARMS="E+L+I" docs/results/ablation/run.sh': "five evolutions of 100 robots (hours)",
    'SEEDS="5 6 7 8 9 10 11 12" ARMS="E+L E+R R+L R+R" ROBOTS=60 JOBS=4 '
    "docs/results/ablation/run.sh": "32 evolutions of 60 robots (hours)",
    'ARENA=cluttered ROBOTS=60 ARMS="E+L E+L+I" SEEDS="0 1 2" docs/results/ablation/run.sh':
        "six evolutions of 60 robots in the cluttered arena (about 1.6 hours)",
    **{f"python evo/main.py +exp=ablation_100k hydra.mode=RUN ga.structure={s} "
       f"learner={learner} seed=0 executor=serial hydra.run.dir=runs/ablation_100k/{m}_seed0":
       "an evolution of 100 robots at 100k env steps each (hours); test_configs composes "
       "+exp=ablation_100k"
       for s, learner, m in (("E", "ppo", "E+L"), ("E", "random", "E+R"),
                             ("R", "ppo", "R+L"), ("R", "random", "R+R"))},
    "python evo/main.py resume=runs/ablation_100k/E+L_seed0":
        "resumes the run above; the README's resume command runs on the smoke run",
    'SEEDS="0 1 2" docs/results/ablation_100k/run.sh': "twelve evolutions (hours)",
    "python -m analysis.report runs/ablation_100k/*_seed[012] --out docs/results/ablation_100k "
    "--first 60": "reads the recordings of the runs above, which are not committed; the "
                  "page's --history-only command reads the committed runs",
    "python -m analysis.early_slope runs/ablation_100k/*_seed[012] --out "
    "docs/results/ablation_100k/early_slope --first 60 --retrained runs/noise/default_100k":
        "reads the runs' recordings and a noise-ceiling folder, neither committed; "
        "test_analysis_report runs analysis.early_slope on the shared ablation",
    "python evo/main.py -m +exp=train seed=0,1,2,3,4 env=clean robot=$ROBOTS env.nthread=1 "
    "hydra.sweep.dir=runs/designer_clean": "20 trainings of 150k env steps (about an hour)",
    "python evo/main.py -m +exp=train seed=0,1,2 env=cluttered robot=$ROBOTS env.nthread=1 "
    "hydra.sweep.dir=runs/designer_cluttered": "12 trainings of 150k env steps in the "
                                               "cluttered arena (about an hour)",
    "python docs/results/designer/table.py runs/designer_clean runs/designer_cluttered "
    "docs/results/designer": "reads the trainings the two sweeps above make",
    "python -m analysis.designer --robots robots --arena clean --seeds 3 --confirm 3 --jobs 2 "
    "--out runs/designer_clean env.nthread=1": "trainings of 150k env steps (about an hour); "
                                               "tests/test_designer.py runs the tool tiny",
    "python -m analysis.designer --robots robots --arena cluttered --seeds 3 --confirm 3 "
    "--jobs 2 --out runs/designer_cluttered env.nthread=1":
        "trainings of 150k env steps (about an hour); tests/test_designer.py runs the tool tiny",
    "python -m analysis.designer --runs runs/ablation_cluttered/E+L_seed* "
    "runs/ablation_cluttered/E+L+I_seed* --robots robots --arena cluttered --seeds 3 "
    "--confirm 6 --jobs 2 --out runs/designer_cluttered env.nthread=1":
        "trainings of 150k env steps (about an hour); tests/test_designer.py runs the tool tiny",
    "python -m analysis.designer --runs runs/ablation/E+L_seed[0-4] runs/ablation/E+L+I_seed[0-4] "
    "--robots robots --arena clean --seeds 3 --confirm 6 --jobs 2 --out runs/designer_clean "
    "env.nthread=1": "trainings of 150k env steps (about an hour); tests/test_designer.py "
                     "runs the tool tiny",
    "for s in 0 1 2; do for i in parent off; do python evo/main.py +exp=inheritance_laptop "
    "ga.inheritance=$i seed=$s hydra.run.dir=runs/inheritance/${i}_seed$s; done; done":
        "six evolutions (hours); test_configs composes +exp=inheritance_laptop",
    "python evo/main.py -m +exp=train seed=0,1,2 env=clean robot=$(ls runs/best/*.json | "
    "paste -sd, -) learner.lmbda=0.95 learner.entropy_coeff=0.005 learner.init_log_std=-0.5 "
    "learner.reward_scaling=false env.nthread=1 hydra.sweep.dir=runs/inh_retrain":
        "trainings of 150k env steps of robots copied from the runs above (about an hour)",
    "python docs/results/designer/table.py runs/inh_retrain docs/results/inheritance/retrained":
        "reads the trainings the sweep above makes",
    **{f"python bench/early_rejection.py runs/paper_clean_timing --margins {m} --predictors "
       f"value curve{c} --out docs/results/early_rejection/paper_clean_seed0{h}.md":
       "reads the learning curves of a +exp=paper_clean run (its recordings, not committed; "
       "about 40 minutes to make); the guide's bench/early_rejection.py command runs on the "
       "smoke run"
       for m, c, h in (("0 0.1 0.2 0.3 0.5", "", ""),
                       ("0.1 0.2 0.3 0.5", " --checkpoints 0.5", "_half"))},
    **{f"python bench/early_rejection.py runs/ablation/E+L_seed0 runs/ablation/R+L_seed0 "
       f"--margins {m} --predictors value curve{c} --out "
       f"docs/results/early_rejection/ablation_seed0{h}.md":
       "reads the learning curves of the 100k ablation's runs (their recordings, not "
       "committed); the guide's bench/early_rejection.py command runs on the smoke run"
       for m, c, h in (("0 0.1 0.2 0.3 0.5 0.8", "", ""),
                       ("0.1 0.2 0.3 0.5", " --checkpoints 0.5", "_half"))},
    "python bench/early_rejection.py runs/paper_clean/seed1 runs/paper_clean/seed2 --margins "
    "0.3 --predictors value --checkpoints 0.5 --out "
    "docs/results/early_rejection/paper_clean_heldout.md":
        "reads the runs' learning curves (their recordings, not committed: the committed "
        "copies keep history, summary and population)",
    "docs/results/early_rejection/run.sh": "six +exp=paper_clean runs (about 4 hours)",
    "bash docs/results/early_rejection/steady_runs.sh":
        "20 evolution runs of 60 robots in +exp=ablation's regime (about 2 h 15 min); "
        "tests/test_early_rejection.py runs the rule in a real evolution",
    "bash docs/results/early_rejection/steady_rate.sh":
        "replays 20 rules on 18 committed runs (minutes); tests/test_rejection.py replays "
        "the rule on two of them through analysis.rejection, which the script's "
        "bench/early_rejection.py calls",
    "python -m analysis.rejection docs/results/ablation/runs/E+L_seed{0..12} "
    "docs/results/ablation/runs/E+L+I_seed{0..4} --first 60 --checkpoints 0.4 --margin 0.6 "
    "--out docs/results/early_rejection/bias":
        "reads 18 committed runs' curves and bodies (a minute); tests/test_rejection.py runs "
        "the same command on two of them and checks what it writes",
    "python -m analysis.equal_cost --without runs/paper_clean --with runs/paper_clean_early "
    "--out docs/results/early_rejection": "reads the six runs run.sh makes (hours); their "
                                          "committed copies keep no config.yaml, which "
                                          "the analysis needs",
    "for t in locomotion push rough; do python evo/main.py +exp=designer retrain.robots=robots "
    "retrain.seeds=5 retrain.confirm=0 env/task=$t hydra.run.dir=runs/handmade/$t; "
    "python -m analysis.designer runs/handmade/$t; done":
        "90 trainings of 150k env steps (hours); tests/test_tasks.py trains in every task",
    "for t in locomotion push rough; do python evo/main.py +exp=task_fidelity env/task=$t "
    "hydra.run.dir=runs/fidelity/$t; python -m analysis.noise_ceiling runs/fidelity/$t; done":
        "three noise ceilings of 48 trainings (about 30 minutes); test_retrain runs the "
        "retrain task end to end",
    "python evo/main.py +exp=task_fidelity env/task=push env.task.t_max=400 "
    "hydra.run.dir=runs/fidelity/push_t400": "48 trainings (about 10 minutes)",
    "python evo/main.py +exp=task_fidelity env/task=rough retrain.budget=100000 "
    "hydra.run.dir=runs/fidelity/rough_100k": "48 trainings of 100k env steps (about 20 minutes)",
    "python evo/main.py +exp=locomotion record=off hydra.sweep.dir=runs/tasks/locomotion":
        "six evolutions of 60 robots (about an hour); tests/test_tasks.py runs a smoke "
        "evolution in a task",
    "python evo/main.py +exp=rough record=off hydra.sweep.dir=runs/tasks/rough":
        "six evolutions of 60 robots (about an hour); tests/test_tasks.py runs a smoke "
        "evolution in a task",
    "python evo/main.py +exp=push record=off hydra.sweep.dir=runs/tasks/push":
        "six evolutions of 60 robots (about an hour); tests/test_tasks.py runs a smoke "
        "evolution in a task",
    **{f'python evo/main.py +exp=designer retrain.robots=robots "retrain.runs=[runs/tasks/{t}]" '
       f"retrain.seeds=5 retrain.confirm=6 env/task={t} hydra.run.dir=runs/designer/{t}":
       "trainings of 150k env steps of the evolutions' best robots and the hand-made ones "
       "(hours); tests/test_designer.py runs +exp=designer tiny"
       for t in ("locomotion", "push", "rough")},
    "python -m analysis.designer runs/designer/locomotion":
        "reads the folder the command above makes; tests/test_designer.py reports on its "
        "tiny one's",
    "for t in reach locomotion push rough; do python evo/main.py +exp=designer "
    "retrain.robots=docs/results/tasks/matrix/bodies retrain.seeds=3 retrain.confirm=0 "
    "env/task=$t hydra.run.dir=runs/matrix/$t; done":
        "84 trainings of 150k env steps (hours); the page's next command remakes the "
        "table from their committed trainings",
    "python -m analysis.tasks reach=runs/matrix/reach locomotion=runs/matrix/locomotion "
    "push=runs/matrix/push rough=runs/matrix/rough --out docs/results/tasks/matrix":
        "writes into docs/results; the page's next command runs it on the committed "
        "trainings",
    **{f"python evo/main.py $P {lever} hydra.run.dir=runs/deployed/{name}":
       "25 to 40 trainings of 150k env steps with periodic evaluation (about an hour); "
       "tests/test_deployed.py trains with each lever"
       for lever, name in (("learner.keep_best=true env=clean", "keep_best_clean"),
                           ("learner.keep_best=true env=cluttered", "keep_best_cluttered"),
                           ("learner.bound_mean=true env=clean", "bound_mean_clean"),
                           ("learner.final_log_std=-2.5 env=clean", "anneal_clean"),
                           ("learner.keep_best=true learner.final_log_std=-2.0 "
                            "learner.anneal_from=0.5 env=cluttered", "late_anneal_cluttered"),
                           ("learner.keep_best=true env.task.observe_stall=true env=clean",
                            "stall_clean"),
                           ("learner.keep_best=true env.task.observe_stall=true env=cluttered",
                            "stall_cluttered"),
                           ("learner.keep_best=true env.task.observe_stall=true "
                            "learner.anneal_lr=false retrain.robots=runs/deployed/robots_rest "
                            "env=cluttered", "const_lr_cluttered_rest"),
                           ("learner.keep_best=true env.task.observe_stall=true "
                            "learner.anneal_lr=false env=clean", "const_lr_clean"))},
    **{f"python evo/main.py $C {lever} hydra.run.dir=runs/deployed/{name}":
       "5 to 40 trainings of 150k env steps with periodic evaluation "
       "(10 minutes to an hour); tests/test_env.py and tests/test_deployed.py check the "
       "stall and range values and a training that observes them"
       for lever, name in (("env.task.stall_seconds=0.5", "stall_fast_cluttered"),
                           ("env.task.observe_stall_count=true", "stall_count_cluttered"),
                           ("env.task.observe_range=true", "range_cluttered"),
                           ("learner.anneal_lr=false", "const_lr_cluttered"),
                           ("learner.epochs=8", "epochs8_cluttered"),
                           ("learner.anneal_lr=false retrain.robots=runs/deployed/robots_gap "
                            "retrain.first_seed=5", "const_lr_cluttered_seeds5to9"),
                           ("learner.anneal_lr=false retrain.robots=runs/deployed/robots_gap_clean "
                            "retrain.first_seed=5 env=clean", "const_lr_clean_seeds5to9"),
                           ("learner.anneal_lr=false retrain.robots=runs/deployed/robots_fw "
                            "retrain.first_seed=5 learner.eval_interval_episodes=32",
                            "const_lr_eval32_fw"),
                           ("learner.anneal_lr=false learner.epochs=8 "
                            "retrain.robots=runs/deployed/robots_gap retrain.seeds=10",
                            "const_lr_epochs8_gap"),
                           ("learner.anneal_lr=false learner.epochs=8 "
                            "retrain.robots=runs/deployed/robots_others",
                            "const_lr_epochs8_cluttered_others"),
                           ("learner.anneal_lr=false learner.epochs=8 "
                            "retrain.robots=runs/deployed/robots env=clean",
                            "const_lr_epochs8_clean"),
                           ("$L retrain.robots=runs/deployed/robots_gap",
                            "const_lr_late_anneal_gap"),
                           ("$L retrain.robots=runs/deployed/robots_others",
                            "const_lr_late_anneal_others"),
                           ("$L retrain.robots=runs/deployed/robots_gap_clean env=clean",
                            "const_lr_late_anneal_gap_clean"),
                           ("$L retrain.robots=runs/deployed/robots_clean_rest env=clean",
                            "const_lr_late_anneal_clean_rest"),
                           ("$L retrain.robots=runs/deployed/robots_gap retrain.first_seed=5",
                            "const_lr_late_anneal_gap_seeds5to9"),
                           ("$L retrain.robots=runs/deployed/robots_gap_clean "
                            "retrain.first_seed=5 env=clean",
                            "const_lr_late_anneal_gap_clean_seeds5to9"),
                           ("$L learner.epochs=8 retrain.robots=runs/deployed/robots_fw "
                            "retrain.seeds=10", "const_lr_epochs8_late_anneal_fw"),
                           ("$L retrain.robots=runs/deployed/robots_cars_rest "
                            "retrain.first_seed=5", "const_lr_late_anneal_cars_seeds5to9"),
                           ("learner.anneal_lr=false env.task.observe_clock=true "
                            "retrain.robots=runs/deployed/robots_gap", "clock_gap"),
                           ("learner.anneal_lr=false env.task.observe_clock=true "
                            "retrain.robots=runs/deployed/robots_gap_clean env=clean",
                            "clock_gap_clean"),
                           ("learner.anneal_lr=false learner.final_log_std=-3.0 "
                            "learner.anneal_from=0.6 retrain.robots=runs/deployed/robots_fw",
                            "narrow_early_fw"))},
    "python evo/main.py $C retrain.robots=runs/deployed/robots_two "
    "learner.total_steps=300000 hydra.run.dir=runs/deployed/stall_300k_cluttered":
        "10 trainings of 300k env steps in the cluttered arena with periodic evaluation "
        "(about 35 minutes)",
    "python docs/results/deployed/table.py keep_best=runs/deployed/keep_best_clean "
    "keep_best=runs/deployed/keep_best_cluttered bound_mean=runs/deployed/bound_mean_clean "
    "anneal=runs/deployed/anneal_clean late_anneal=runs/deployed/late_anneal_cluttered "
    "stall=runs/deployed/stall_clean stall=runs/deployed/stall_cluttered "
    "stall_fast=runs/deployed/stall_fast_cluttered "
    "stall_count=runs/deployed/stall_count_cluttered "
    "range=runs/deployed/range_cluttered stall_300k=runs/deployed/stall_300k_cluttered "
    "const_lr=runs/deployed/const_lr_cluttered const_lr=runs/deployed/const_lr_cluttered_rest "
    "const_lr=runs/deployed/const_lr_clean epochs8=runs/deployed/epochs8_cluttered "
    "const_lr_seeds5to9=runs/deployed/const_lr_cluttered_seeds5to9 "
    "const_lr_seeds5to9=runs/deployed/const_lr_clean_seeds5to9 "
    "eval32=runs/deployed/const_lr_eval32_fw "
    "const_lr_epochs8=runs/deployed/const_lr_epochs8_gap "
    "const_lr_epochs8=runs/deployed/const_lr_epochs8_cluttered_others "
    "const_lr_epochs8=runs/deployed/const_lr_epochs8_clean "
    "const_lr_late_anneal=runs/deployed/const_lr_late_anneal_gap "
    "const_lr_late_anneal=runs/deployed/const_lr_late_anneal_others "
    "const_lr_late_anneal=runs/deployed/const_lr_late_anneal_gap_clean "
    "const_lr_late_anneal=runs/deployed/const_lr_late_anneal_clean_rest "
    "const_lr_late_anneal_seeds5to9=runs/deployed/const_lr_late_anneal_gap_seeds5to9 "
    "const_lr_late_anneal_seeds5to9=runs/deployed/const_lr_late_anneal_gap_clean_seeds5to9 "
    "const_lr_late_anneal_seeds5to9=runs/deployed/const_lr_late_anneal_cars_seeds5to9 "
    "const_lr_epochs8_late_anneal=runs/deployed/const_lr_epochs8_late_anneal_fw "
    "clock=runs/deployed/clock_gap clock=runs/deployed/clock_gap_clean "
    "narrow_early=runs/deployed/narrow_early_fw --out docs/results/deployed":
        "reads the trainings the commands above make",
    "python docs/results/deployed/reevaluate.py "
    "const_lr_late_anneal=runs/deployed/const_lr_late_anneal_gap "
    "const_lr_late_anneal=runs/deployed/const_lr_late_anneal_others "
    "const_lr_late_anneal=runs/deployed/const_lr_late_anneal_gap_clean "
    "const_lr_late_anneal=runs/deployed/const_lr_late_anneal_clean_rest "
    "--out docs/results/deployed/reevaluated.csv":
        "runs the policies of the trainings the commands above make on 100 more episodes "
        "each (about 2 minutes per cluttered training)",
    **{"python docs/results/deployed/reevaluate.py "
       f"const_lr_epochs8=runs/deployed/const_lr_epochs8_gap --robots {robots} "
       "--out docs/results/deployed/reevaluated.csv":
       "runs the policies of the trainings a command above makes on 100 more episodes "
       "each (about 2 minutes per training)"
       for robots in ("four_wheeler", "snake --seeds 0 1 2 3 4")},
    "python docs/results/deployed/mechanism.py runs/deployed/stall_cluttered "
    "four_wheeler_seed1 four_wheeler_seed4 --out docs/results/deployed/mechanism_stall.csv":
        "reads the trainings' recordings, which the commands above make",
    "python docs/results/deployed/mechanism.py runs/deployed/range_cluttered "
    "four_wheeler_seed2 crawler_seed3 --out docs/results/deployed/mechanism_range.csv":
        "reads the trainings' recordings, which the commands above make",
    "python docs/results/deployed/mechanism.py runs/deployed/keep_best_clean snake_seed0 "
    "--out docs/results/deployed/mechanism.csv": "reads a training's recordings, which the "
                                                 "commands above make",
    "python docs/results/deployed/mechanism.py runs/deployed/late_anneal_cluttered "
    "four_wheeler_seed2 crawler_seed4 --out docs/results/deployed/mechanism_cluttered.csv":
        "reads the trainings' recordings, which the commands above make",
    "python evo/main.py +exp=retrain record=off seed=1000 retrain.random=32 retrain.seeds=3 "
    "retrain.budget=50000 retrain.baseline=false learner.gamma=0.99 learner.lmbda=0.8 "
    "learner.epochs=4 learner.minibatch_size=1024 learner.entropy_coeff=0.0 "
    "learner.init_log_std=-1.0 learner.policy_out_gain=0.01 learner.reward_scaling=true "
    "learner.hidden=[128,128] env.task.observe_up=false physics_step=dt6p25ms_x8 "
    "env.task.observe_stall=true hydra.run.dir=runs/noise/heldout_stall":
        "96 trainings of 50k env steps (about 15 minutes on 2 cores); test_configs composes "
        "+exp=retrain",
    "python -m analysis.noise_ceiling runs/noise/heldout_stall":
        "reads the trainings the command above makes",
    "docs/results/noise_sweep/levers/run.sh": "five noise ceilings of 32 trainings (hours)",
    "python evo/main.py +exp=paper_cluttered hydra.run.dir=runs/paper_cluttered_final":
        "the paper's run in the cluttered arena (hours); test_configs composes it",
    "python evo/main.py resume=runs/paper_cluttered_final":
        "resumes the run above; the README's resume command runs on the smoke run",
    "cp runs/paper_cluttered_final/{history.csv,summary.json} docs/results/paper_cluttered/":
        "copies the run above's files into docs/results",
    "python evo/main.py +exp=paper_cluttered hydra.run.dir=runs/paper_cluttered_timing":
        "the paper's run in the cluttered arena (hours); test_configs composes it",
}
"""Commands a test cannot run, each with its reason."""

TINY_EVOLUTION = (  # six robots of four to six short batches, episodes ending in every one
    "executor=serial record.rerun=false env.task.t_max=40 learner.num_envs=8 "
    "learner.rollout_steps=32 learner.epochs=2 learner.minibatch_size=128 "
    "ga.population_size=3 ga.robot_budget=6 "
    "ga.schedule.initial=1024 ga.schedule.first=1024 ga.schedule.last=1536"
)
TINY_TRAINING = ("learner.num_envs=4 learner.rollout_steps=64 learner.epochs=1 "
                 "learner.minibatch_size=128 learner.eval_episodes=2 env.task.t_max=100")


@dataclass(frozen=True)
class How:
    """How a test runs one README command (the default: as written, in test_readme.py).

    Attributes:
        append: Arguments appended to make it small (Hydra overrides or its own flags).
        env: Environment variables added, ``KEY=value`` separated by spaces (sizes).
        fill: (placeholder, key of :data:`PLACES`) pairs, each filling the first
            occurrence of the placeholder, where the placeholder's own entry does not fit.
        makes: Files it must leave (glob patterns, placeholders filled, from the root);
            they are removed before it runs.
        says: Text its standard output must hold.
        makes_run: The name under which the run directory it creates is kept for
            :data:`PLACES`; such a command runs first, when its test file starts.
        group: ``"main"`` (tests/test_readme.py, around the smoke run), ``"results"``
            (tests/test_results_commands.py: the results pages' analyses of the
            committed data) or ``"analysis"``
            (tests/test_analysis_report.py, around the ablation it shares with the
            analysis tests).
        long: A variant of a command the default tier already runs (other options of
            the same script): it runs in the long tier (``pytest -m long``).
    """

    append: str = ""
    env: str = ""
    fill: tuple[tuple[str, str], ...] = ()
    makes: tuple[str, ...] = ()
    says: str = ""
    makes_run: str = ""
    group: str = "main"
    long: bool = False


THROUGHPUT = ("env.task.t_max=50 --steps 256 --robots robots/four_wheeler.json "
              "--arenas clean")  # overrides first: the README line may end in overrides
SMALL_THROUGHPUT = f"learner.num_envs=16 learner.minibatch_size=128 {THROUGHPUT}"
ANALYSIS = "analysis"
RESULTS = "results"
ER = "docs/results/early_rejection"


def deployed_robots(folder: str, files: str, makes: str) -> tuple[str, How]:
    """The results page's command that gathers ``files`` into ``runs/deployed/<folder>/``
    for a comparison's trainings, and how it is run: it must leave ``<folder>/<makes>``."""
    return (f"mkdir -p runs/deployed/{folder} && cp {files} runs/deployed/{folder}/",
            How(makes=(f"runs/deployed/{folder}/{makes}",), group=RESULTS))


HOW: dict[str, How] = {
    # ---- the runs the others read, made first
    "python evo/main.py +exp=smoke": How(makes_run="smoke", says="best robot:"),
    "python evo/main.py +exp=train robot=robots/four_wheeler.json": How(
        append=f"learner.total_steps=1024 {TINY_TRAINING}", makes_run="train",
        says="deterministic evaluation:"),
    "python evo/main.py +exp=ablation": How(
        append=TINY_EVOLUTION, makes_run="ablation",
        group=ANALYSIS),
    # ---- the docs
    "MUJOCO_GL=egl bash docs/gallery.sh": How(
        append=f"gallery_test learner.total_steps=1024 {TINY_TRAINING}",
        env="GALLERY_ONLY=reach_clean_designed",
        makes=("gallery_test/reach_clean_designed.webm",)),
    # ---- evo
    "python evo/main.py +exp=deploy robot=robots/steering_car.json": How(
        append=f"learner.total_steps=1024 {TINY_TRAINING}", says="deterministic evaluation:"),
    "python evo/main.py +exp=train robot=robots/snake.json env/task=locomotion": How(
        append=f"learner.total_steps=1024 {TINY_TRAINING}", says="deterministic evaluation:"),
    "python evo/main.py +exp=evaluate robot=robots/four_wheeler.json "
    "checkpoint=<run dir>/policy.pt": How(append=TINY_TRAINING,
                                          fill=(("<run dir>", "<train run dir>"),),
                                          says="over 2 deterministic episodes",
                                          makes_run="evaluate"),
    "python evo/main.py resume=<run dir>": How(says="robots evaluated"),
    "python -m evo.replay <run dir> <robot name> --video out.mp4 --rrd out.rrd": How(
        makes=("out.mp4", "out.rrd")),
    "python -m evo.replay --gallery <run dir>": How(append="--top 2",
                                                   makes=("<run dir>/best.png",)),
    "python evo/main.py task=robots robots.count=8": How(makes=("outputs/*/*/robots/*.png",)),
    # ---- analysis
    "python -m analysis.report outputs/ablation/<date> --out report/": How(
        append="--resamples 100", makes=("report/report.md", "report/*.png"), group=ANALYSIS),
    "python -m analysis.report outputs/ablation/<date> --out report/ --first 60": How(
        append="--resamples 100", makes=("report/report.md",), group=ANALYSIS),
    "python -m analysis.early_slope outputs/ablation/<date> --out early/": How(
        append="--resamples 100", makes=("early/early_slope.md", "early/*.png"), group=ANALYSIS),
    "python -m analysis.early_slope outputs/ablation/<date> --out early/ --retrained <dirs>":
        How(append="--resamples 100", makes=("early/early_slope.md",), group=ANALYSIS),
    "python -m analysis.equal_cost --without <runs> --with <runs> --out cost/": How(
        fill=(("<runs>", "<runs without>"), ("<runs>", "<runs with>")),
        makes=("cost/equal_cost.md", "cost/equal_cost.png"), group=ANALYSIS),
    "EVO_RUNS=outputs/ablation/<date> jupyter execute analysis/ablation.ipynb": How(
        env="EVO_RESAMPLES=100 EVO_FIGURES=figures/ablation",
        makes=("figures/ablation/*.png",), group=ANALYSIS),
    "EVO_RUNS=outputs/ablation/<date> jupyter execute analysis/early_slope.ipynb": How(
        env="EVO_RESAMPLES=100 EVO_FIGURES=figures/early_slope",
        makes=("figures/early_slope/*.png",), group=ANALYSIS),
    # ---- benchmarks, at their smallest
    "python bench/robots.py": How(append="--count 200 --pairs 50"),
    "python bench/env_throughput.py": How(
        append="--steps 20 --robots robots/four_wheeler.json --num-envs 12 --nthread 1 "
               "--arenas clean --repeats 1"),
    "python bench/train_throughput.py": How(append=SMALL_THROUGHPUT),
    "python bench/train_throughput.py --profile": How(append=SMALL_THROUGHPUT, long=True),
    "python bench/train_throughput.py --steps 150000 --quality": How(append=SMALL_THROUGHPUT,
                                                                    long=True),
    "python bench/train_throughput.py learner.num_envs=32 learner.rollout_steps=64": How(
        append=THROUGHPUT, long=True),
    "python bench/ppo_floor.py": How(
        append="--repeats 1 learner.num_envs=4 learner.rollout_steps=64 "
               "learner.minibatch_size=128"),
    "python bench/record_overhead.py": How(append="--steps 1024 --repeats 1"),
    "python bench/soak.py --executor local serial ray": How(
        append="--evals 4 --every 2 --executor serial", says="after the first"),
    "python bench/physics_step.py": How(
        append="--robots robots/four_wheeler.json --seconds 0.5 --arenas 2 --num-envs 4 "
               "--rate-steps 10", says="verdict"),
    # ---- the results pages: their analyses read the committed data again (outputs
    # redirected out of docs/results by a second --out, which wins)
    "mkdir -p runs && cp -r docs/results/ablation/runs runs/ablation": How(
        makes=("runs/ablation/E+L_seed0/history.csv",), group=RESULTS),
    "python -m analysis.report runs/ablation --out docs/results/ablation --history-only "
    "--first 60": How(append="--out check/ablation --resamples 200",
                      makes=("check/ablation/report.md",), group=RESULTS),
    "python -m analysis.power runs/ablation --history-only --first 60": How(
        says="E+L − R+L", group=RESULTS),
    "python -m analysis.power runs/ablation --history-only --first 60 --pair E+L+I E+L": How(
        says="E+L+I − E+L", group=RESULTS),
    "python -m analysis.report docs/results/ablation_100k/runs --history-only --first 60 "
    "--out docs/results/ablation_100k": How(append="--out check/ablation_100k --resamples 200",
                                            makes=("check/ablation_100k/report.md",),
                                            group=RESULTS),
    "python -m analysis.power docs/results/ablation_100k/runs --history-only --first 60": How(
        says="E+L − R+L", group=RESULTS),
    "python -m analysis.report docs/results/ablation_cluttered/runs --out "
    "docs/results/ablation_cluttered/report --history-only": How(
        append="--out check/ablation_cluttered --resamples 200",
        makes=("check/ablation_cluttered/report.md",), group=RESULTS),
    "python -m analysis.inheritance docs/results/ablation/runs/E+L_seed[0-4] "
    "docs/results/ablation/runs/E+L+I_seed[0-4] --out docs/results/inheritance/ablation": How(
        append="--out check/inheritance_ablation",
        makes=("check/inheritance_ablation/report.md", "check/inheritance_ablation/*.png"),
        group=RESULTS),
    "python -m analysis.inheritance docs/results/inheritance/runs --out docs/results/inheritance":
        How(append="--out check/inheritance", makes=("check/inheritance/report.md",),
            group=RESULTS),
    "python -m analysis.tasks reach=docs/results/tasks/matrix/reach "
    "locomotion=docs/results/tasks/matrix/locomotion push=docs/results/tasks/matrix/push "
    "rough=docs/results/tasks/matrix/rough --out matrix/": How(
        makes=("matrix/matrix.md", "matrix/matrix.png"), group=RESULTS),
    **dict(deployed_robots(folder, files, makes) for folder, files, makes in (
        ("robots", "robots/*.json robots/held_out/*.json", "snake.json"),
        ("robots_fw", "robots/four_wheeler.json", "four_wheeler.json"),
        ("robots_clean_rest", "robots/four_wheeler.json robots/steering_car.json "
         "robots/twisted_four_wheeler.json robots/inchworm.json robots/held_out/*.json",
         "crawler.json"),
        ("robots_cars_rest", "robots/steering_car.json robots/held_out/crawler.json",
         "crawler.json"),
        ("robots_gap", "robots/four_wheeler.json robots/snake.json", "snake.json"),
        ("robots_gap_clean", "robots/snake.json robots/scoop_car.json", "snake.json"),
        ("robots_others", "robots/steering_car.json robots/twisted_four_wheeler.json "
         "robots/scoop_car.json robots/inchworm.json robots/held_out/*.json", "crawler.json"),
        ("robots_rest", "robots/inchworm.json robots/scoop_car.json robots/snake.json "
         "robots/twisted_four_wheeler.json robots/held_out/six_wheeler.json", "snake.json"),
        ("robots_two", "robots/four_wheeler.json robots/held_out/crawler.json",
         "crawler.json"),
        ("robots_cars", "robots/four_wheeler.json robots/steering_car.json "
         "robots/held_out/crawler.json", "crawler.json"))),
    "mkdir -p runs && cp -r docs/results/noise_sweep/study runs/noise_sweep": How(
        makes=("runs/noise_sweep/*",), group=RESULTS),
    **{f"python -m analysis.equal_cost --without {ER}/runs/ablation/{arm}_seed* --with "
       f"{ER}/runs/ablation_early/{arm}_seed* --out {ER}/steady_runs/{arm}": How(
           append=f"--out check/steady_{arm}", makes=(f"check/steady_{arm}/equal_cost.md",),
           group=RESULTS) for arm in ("E+L+I", "E+L")},
    f"python {ER}/headline.py E+L+I+rule={ER}/runs/ablation_early/E+L+I_seed{{0..4}} "
    f"E+L={ER}/runs/ablation/E+L_seed{{0..4}} --against E+L --targets 1.05 0.9 0.8 "
    f"--out {ER}/steady_runs/headline.md": How(
        append="--out check/headline.md", makes=("check/headline.md",), says="Medians",
        group=RESULTS),
    # ---- the results pages' benchmarks: variants of the benchmarks above, small
    "python bench/env_throughput.py --arenas clean locomotion push rough --num-envs 32 "
    "--nthread 1 --steps 200": How(append="--steps 10 --num-envs 4 --repeats 1 --robots "
                                          "robots/four_wheeler.json", long=True),
    "python bench/train_throughput.py --arenas clean locomotion push rough --robots "
    "robots/four_wheeler.json robots/snake.json": How(
        append="--steps 256 learner.num_envs=16 learner.minibatch_size=128 env.task.t_max=50",
        long=True),
    "python bench/train_throughput.py --steps 20480 --arenas clean --nthread 1 "
    "learner.num_envs=32 learner.rollout_steps=64 learner.lr=3e-4 learner.minibatch_size=1024 "
    "learner.lmbda=0.8 learner.entropy_coeff=0 learner.init_log_std=-1 "
    "learner.reward_scaling=true physics_step=dt6p25ms_x8": How(append=THROUGHPUT, long=True),
    **{f"python bench/soak.py --executor {executor} --evals 1000 --every 100": How(
        append="--evals 4 --every 2", says="after the first", long=True)
       for executor in ("local", "serial", "ray")},
}
"""Per command: how it is run, where that is not exactly as written."""


@dataclass(frozen=True)
class Made:
    """The run directories the README's first commands made, by name, under ``root``."""

    root: Path
    runs: dict[str, Path] = field(default_factory=dict)
    strays: dict[str, list[str]] = field(default_factory=dict)
    """Per run: what its command wrote into the root outside ``outputs/``."""

    def rel(self, name: str, start: str = "") -> str:
        """Run ``name``'s path relative to ``root / start`` (as a user would type it)."""
        return str(self.runs[name].relative_to(self.root / start))

    def best(self, name: str) -> str:
        """The best robot of run ``name``."""
        return str(json.loads((self.runs[name] / "summary.json").read_text())["best_robot"])

    def job(self, method: str) -> str:
        """The ablation's job of ``method`` (GA seed 0), relative to ``root``."""
        return self.rel("ablation") + f"/{method}_seed0"


PLACES: dict[str, Callable[[Made], str]] = {
    "<run dir>": lambda m: m.rel("smoke"),
    "<run>": lambda m: m.rel("smoke", "outputs"),
    "<robot name>": lambda m: m.best("smoke"),
    "<name>": lambda m: m.best("smoke"),
    "RUN...": lambda m: m.rel("smoke"),
    "<train run dir>": lambda m: m.rel("train"),
    "<date>": lambda m: m.runs["ablation"].name,
    "<dirs>": lambda m: m.job("E+L"),
    "<runs without>": lambda m: m.job("E+L"),
    "<runs with>": lambda m: m.job("R+L"),
}
"""Placeholder -> its value, from the runs the README's first commands made."""


# ---------------------------------------------------------------- running them


def how(command: Command) -> How:
    """How ``command`` is run (the default for a command no table names)."""
    return HOW.get(command.text, How())


def group(name: str) -> list[Command]:
    """The commands test file ``name`` runs after its first runs, in the pages' order."""
    return [c for c in readme_commands() if c.text not in EXCLUDED
            and how(c).group == name and not how(c).makes_run]


def filled(text: str, entry: How, made: Made) -> str:
    """``text`` with its placeholders filled from ``made``.

    Raises:
        KeyError: Naming a placeholder :data:`PLACES` has no entry for.
    """
    for placeholder, key in entry.fill:
        text = text.replace(placeholder, PLACES[key](made), 1)
    for placeholder in sorted(set(PLACEHOLDER.findall(text)), key=len, reverse=True):
        if placeholder not in PLACES:
            raise KeyError(f"no value for {placeholder}: add it to PLACES in {__file__}")
        text = text.replace(placeholder, PLACES[placeholder](made))
    return text


def copy_of_the_root(folder: Path) -> Path:
    """A folder that looks like the repository root: a link to each of its entries but
    those git ignores (outputs, runs), and a ``.venv`` that is this interpreter's."""
    ignored = [line.strip().strip("/") for line in (REPO / ".gitignore").read_text().splitlines()
               if line.strip() and not line.startswith("#")]
    for entry in REPO.iterdir():
        if not entry.name.startswith(".") and not any(
                fnmatch.fnmatch(entry.name, pattern) for pattern in ignored):
            (folder / entry.name).symlink_to(entry)
    venv = folder / ".venv"
    if sys.prefix != sys.base_prefix:
        venv.symlink_to(sys.prefix)
    else:  # no virtualenv: an activate script that puts this interpreter first
        (venv / "bin").mkdir(parents=True)
        (venv / "bin" / "activate").write_text(
            f'export PATH="{Path(sys.executable).parent}:$PATH"\n')
    return folder


def environment(extra: str = "") -> Mapping[str, str]:
    """The commands' environment: this interpreter's bin folder first on ``PATH``,
    this checkout importable, offscreen rendering, and ``extra`` (``KEY=value ...``)."""
    env = {**os.environ, "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl"), "COLUMNS": "120",
           "PYTHONPATH": os.pathsep.join(filter(None, [str(REPO), os.environ.get("PYTHONPATH")])),
           "PATH": os.pathsep.join([str(Path(sys.executable).parent), os.environ["PATH"]])}
    env.update(pair.split("=", 1) for pair in extra.split())
    return env


def run(command: Command, root: Path, made: Made) -> subprocess.CompletedProcess[str]:
    """Run ``command`` (its setup lines first) with bash in ``root``; check that it
    exits 0, leaves what :attr:`How.makes` names and prints :attr:`How.says`."""
    entry = how(command)
    text = filled(f"{command.text} {entry.append}".strip(), entry, made)
    makes = [filled(pattern, entry, made) for pattern in entry.makes]
    for pattern in makes:
        for path in root.glob(pattern):
            path.unlink()
    script = "\n".join([*command.setup, text])
    done = subprocess.run(["bash", "-ec", script], cwd=root, env=environment(entry.env),
                          capture_output=True, text=True, timeout=900)
    assert done.returncode == 0, f"{text}\nexit {done.returncode}\n{done.stderr[-3000:]}"
    for pattern in makes:
        found = [p for p in root.glob(pattern) if p.is_file() and p.stat().st_size > 0]
        assert found, f"{text}\nleft no {pattern}"
    assert entry.says in done.stdout, f"{text}\nprinted no {entry.says!r}:\n{done.stdout[-2000:]}"
    return done


def run_first(name: str, root: Path) -> Made:
    """Run group ``name``'s commands that make runs, in README order, and return them."""
    made = Made(root)
    for command in readme_commands():
        entry = how(command)
        if entry.group != name or not entry.makes_run or command.text in EXCLUDED:
            continue
        before, entries = set(root.glob("outputs/**/")), set(root.iterdir())
        run(command, root, made)
        made.strays[entry.makes_run] = sorted(
            p.name for p in set(root.iterdir()) - entries if p.name != "outputs")
        new = sorted((p for p in set(root.glob("outputs/**/")) - before
                      if (p / "summary.json").is_file() or (p / "multirun.yaml").is_file()),
                     key=lambda p: len(p.parts))
        assert new, f"{command.text} made no run directory in outputs/"
        made.runs[entry.makes_run] = new[0]
    return made
