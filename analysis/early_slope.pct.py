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
# # Early-slope study (paper §8, §9)
#
# Does the start of a learning curve predict a robot's fitness? The report of
# `python -m analysis.early_slope`, step by step, on the runs named by the environment
# variable `EVO_RUNS` (run directories or a multirun folder, separated by `os.pathsep`)
# and, for the noise ceiling, `EVO_RETRAINED` (directories of retrained structures;
# empty: no ceiling), or by the parameters cell below:
#
# ```bash
# EVO_RUNS=outputs/ablation/<date> jupyter execute analysis/early_slope.ipynb
# jupyter lab analysis/     # then set runs_path below, or start it with EVO_RUNS=... set
# ```
#
# Relative paths are read from the directory `jupyter` was started in (the repository
# root above), not from `analysis/` where the kernel runs.

# %%
import os
import tempfile
from pathlib import Path

from IPython.display import Image, Markdown, display

from analysis import early_slope as es
from analysis.early_slope.report import (
    REJECTION_COLUMNS,
    correlation_table,
    early_slope_figures,
    early_slope_study,
    recall_table,
)
from analysis.load import launch_paths, load_retrained, load_runs
from analysis.stats import Resampling

# %% tags=["parameters"]
runs_path = os.environ.get("EVO_RUNS", "outputs/ablation")  # run dirs, os.pathsep-separated
retrained_path = os.environ.get("EVO_RETRAINED", "")  # retrained structures; empty: none
figures_dir = os.environ.get("EVO_FIGURES", "")  # where the PNGs go; empty: a temporary folder
seed = 0  # bootstrap seed (the CLI's --seed)
resamples = int(os.environ.get("EVO_RESAMPLES", "2000"))  # per interval (--resamples)

# %% [markdown]
# ## The runs and the robots studied

# %%
runs = load_runs(launch_paths(runs_path))
retrained = load_retrained(launch_paths(retrained_path)) if retrained_path else None
study = early_slope_study(runs.robots, runs.curves, Resampling.seeded(seed, resamples),
                          population_size=runs.population_sizes, retrained=retrained)
for note in [*runs.notes, *study.notes]:
    display(Markdown(f"- {note}"))
display(runs.runs.drop(columns="path"))

# %% [markdown]
# ## Noise ceiling

# %%
display(study.ceiling if study.ceiling is not None
        else "absent: no retrained structures given (EVO_RETRAINED)")

# %% [markdown]
# ## Rank correlation with the final fitness, and with the return after the cut

# %%
for target in es.TARGETS:
    display(Markdown(f"### target: {target}"), correlation_table(study.metrics, target))

# %% [markdown]
# ## Top-10 % recall per cut and predictor

# %%
display(recall_table(study.metrics, "fitness"))

# %% [markdown]
# ## Early rejection: env steps saved against fitness lost

# %%
display(Markdown("### reject the lowest quarter of predictions"),
        study.rejection[REJECTION_COLUMNS])
display(Markdown("### reject below the population minimum"),
        study.rejection_population[REJECTION_COLUMNS])

# %% [markdown]
# ## Figures

# %%
folder = (launch_paths(figures_dir)[0] if figures_dir
          else Path(tempfile.mkdtemp(prefix="early-slope-")))
figures = early_slope_figures(study, folder)
for stem in figures:
    display(Markdown(f"### {stem}"), Image(filename=folder / f"{stem}.png"))
