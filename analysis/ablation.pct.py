# ---
# jupyter:
#   jupytext:
#     formats: ipynb,.pct.py:percent
#     text_representation:
#       extension: .py
#       format_name: percent
#       format_version: '1.3'
#       jupytext_version: 1.19.6
#   kernelspec:
#     display_name: Python 3
#     language: python
#     name: python3
# ---

# %% [markdown]
# # Ablation: R+R, R+L, E+R, E+L (paper §8)
#
# The ablation report of `python -m analysis.report`, step by step, on the runs named by
# the environment variable `EVO_RUNS` (run directories or a multirun folder, separated by
# `os.pathsep`), or by the parameters cell below (papermill can set it):
#
# ```bash
# EVO_RUNS=outputs/ablation/<date> jupyter execute analysis/ablation.ipynb
# jupyter lab analysis/     # then set runs_path below, or start it with EVO_RUNS=... set
# ```
#
# Relative paths are read from the directory `jupyter` was started in (the repository
# root above), not from `analysis/` where the kernel runs.
#
# Every number comes from the library functions the report uses
# (`analysis.load`, the study's package `analysis.ablation`, `analysis.stats`,
# `analysis.plots`).

# %%
import os
import tempfile
from pathlib import Path

from IPython.display import Image, Markdown, display

from analysis.ablation.nested_report import nested_markdown
from analysis.ablation.report import ablation_figures, ablation_tables, tests_markdown
from analysis.load import launch_paths, load_runs
from analysis.stats import Resampling

# %% tags=["parameters"]
runs_path = os.environ.get("EVO_RUNS", "outputs/ablation")  # run dirs, os.pathsep-separated
figures_dir = os.environ.get("EVO_FIGURES", "")  # where the PNGs go; empty: a temporary folder
seed = 0  # bootstrap seed (the report's --seed)
resamples = int(os.environ.get("EVO_RESAMPLES", "2000"))  # per interval (--resamples)

# %% [markdown]
# ## The runs

# %%
runs = load_runs(launch_paths(runs_path))
for note in runs.notes:
    display(Markdown(f"- {note}"))
display(runs.runs.drop(columns="path"))

# %% [markdown]
# ## Fitness per method, with bootstrap CIs

# %%
tables = ablation_tables(runs.robots, Resampling.seeded(seed, resamples),
                        population_size=runs.population_size)
for note in tables.notes:
    display(Markdown(f"- {note}"))
display(tables.budgets, tables.main)

# %% [markdown]
# ## Tests: Kruskal–Wallis, pairwise Mann–Whitney U (Holm) and A12

# %%
display(Markdown(tests_markdown("robots", tables.kruskal, tables.pairwise)))
if tables.per_run is not None:
    display(Markdown(tests_markdown("per-run means", *tables.per_run)))

# %% [markdown]
# ## Interaction contrast: (E+L − R+L) − (E+R − R+R)

# %%
display(tables.interaction if tables.interaction is not None
        else f"not computed; missing: {tables.missing}")

# %% [markdown]
# ## Runs as the unit: Welch's t on run means, the mixed model, the seeds needed

# %%
display(Markdown(nested_markdown(tables.nested)) if tables.nested is not None
        else "not computed: needs two or more GA seeds per method")

# %% [markdown]
# ## Beside the paper (reward scales differ: compare the ordering, not the values)

# %%
display(tables.paper)

# %% [markdown]
# ## The paper's figures

# %%
folder = (launch_paths(figures_dir)[0] if figures_dir
          else Path(tempfile.mkdtemp(prefix="ablation-")))
figures = ablation_figures(runs.robots, runs.curves, folder,
                           population_size=runs.population_size)
for stem in figures:
    display(Markdown(f"### {stem}"), Image(filename=folder / f"{stem}.png"))
