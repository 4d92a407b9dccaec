"""The ablation report's sections with the GA run as the unit (:mod:`analysis.ablation.nested`).

:func:`nested_tables` computes them from a robots table; :func:`nested_markdown`
writes them; :func:`analysis.ablation.report.ablation_tables` and
:func:`analysis.ablation.report.ablation_markdown` call both. Each question of the ablation
(:data:`analysis.ablation.nested.PAIRS` and the interaction, and E+L+I vs E+L when the fifth arm
is there: :data:`analysis.ablation.nested.EXTRA_PAIRS`) gets one answering test, Welch's t-test
on the runs' mean fitness, and the mixed model beside it.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from analysis.ablation import nested, power
from analysis.markdown import fmt_ci, fmt_number, markdown_table
from analysis.tables import EXTRA_METHODS, method_order

MIN_RUNS = 2
"""GA seeds every method needs before the run-level sections are computed."""
POWER_PAIR = ("E+L", "R+L")


@dataclass
class NestedTables:
    """The run-level tables of the report.

    Attributes:
        runs: :func:`analysis.ablation.nested.run_summaries`.
        means: Per method and run summary, the mean over runs with a t interval.
        run_tests: :func:`analysis.ablation.nested.run_level_tests`.
        mixed: :func:`analysis.ablation.nested.mixed_model_tests`.
        components: :func:`analysis.ablation.nested.variance_components`.
        power: :func:`analysis.ablation.power.power_table` for :data:`POWER_PAIR`, or None.
        notes: Sentences on what was left out.
    """

    runs: pd.DataFrame
    means: pd.DataFrame
    run_tests: pd.DataFrame
    mixed: pd.DataFrame
    components: pd.DataFrame
    power: pd.DataFrame | None
    notes: list[str] = field(default_factory=list)


def nested_tables(robots: pd.DataFrame, population_size: int, rng: np.random.Generator
                  ) -> NestedTables | None:
    """The run-level tables, or None when a method has fewer than :data:`MIN_RUNS` runs
    (a method of the paper's; an extra arm with fewer leaves only its question
    untested).

    Args:
        robots: Robots table, fully trained robots only.
        population_size: Initial population size (for the final population's mean).
        rng: Randomness of the power simulation.
    """
    per_method = robots.groupby("method")["run"].nunique()
    paper = per_method.drop(list(EXTRA_METHODS), errors="ignore")
    if (paper if len(paper) else per_method).min() < MIN_RUNS:
        return None
    runs = nested.run_summaries(robots, population_size)
    means = pd.concat([nested.run_level_means(runs, s).assign(summary=s)
                       for s in nested.RUN_SUMMARIES], ignore_index=True)
    notes = _extra_notes(per_method)
    mixed = nested.mixed_model_tests(robots)
    if not mixed["converged"].all():
        notes.append("The mixed model did not converge for: "
                     + ", ".join(mixed.loc[~mixed["converged"], "question"]) + ".")
    table = None
    if set(POWER_PAIR) <= set(robots["method"]):
        table = power.power_table(robots, POWER_PAIR, rng=rng)
    else:
        notes.append(f"Power analysis needs {' and '.join(POWER_PAIR)}; not computed.")
    return NestedTables(runs=runs, means=means, run_tests=nested.run_level_tests(runs),
                        mixed=mixed, components=nested.variance_components(robots),
                        power=table, notes=notes)


def _extra_notes(runs_per_method: pd.Series) -> list[str]:
    """What the arms beyond the paper's four answer, and how (none when absent)."""
    notes = []
    for method in (m for m in EXTRA_METHODS if m in runs_per_method.index):
        asked = [nested.question_name(a, b) for a, b in nested.EXTRA_PAIRS if method in (a, b)]
        notes.append(f"{method} answers {', '.join(asked)}: its own test, outside the Holm "
                     "family of the paper's three pairs (its p_holm is its p; the paper's "
                     f"p-values are the same without it). {method}'s fitness includes what "
                     "its robots inherited: it measures policy and body together, not the "
                     "body alone.")
        if runs_per_method[method] < MIN_RUNS:
            notes.append(f"{method} has {runs_per_method[method]} run(s); Welch's test "
                         f"needs {MIN_RUNS} or more, so its question is not decided yet.")
    return notes


def write_nested_tables(t: NestedTables, out: Path) -> list[Path]:
    """The run-level tables as CSV beside the report: ``runs.csv`` (per-run summaries),
    ``nested_tests.csv`` (both tests of every question, column ``test``) and
    ``power.csv``; returns the paths written."""
    written = [out / "runs.csv", out / "nested_tests.csv"]
    t.runs.to_csv(written[0], index=False)
    pd.concat([t.run_tests.assign(test="welch_run_level"),
               t.mixed.assign(test="mixed_model", summary="fitness")],
              ignore_index=True).to_csv(written[1], index=False)
    if t.power is not None:
        written.append(out / "power.csv")
        t.power.to_csv(written[2], index=False)
    return written


# ---------------------------------------------------------------- Markdown

UNIT_NOTE = (
    "Robots are nested in GA runs: the robots of one evolved run share ancestors, and "
    "the question \"does method a beat method b\" is about what another GA run would "
    "give. Each question is therefore answered with the run as the unit: **Welch's "
    "t-test on the runs' mean fitness** (one value per run; Holm over the three pairs "
    "E+L vs R+L, R+L vs E+R, E+R vs R+R; the interaction is its own test, a Welch "
    "contrast of the four methods' run means with Satterthwaite df). Beside it, a "
    "**linear mixed model** on robots (statsmodels `MixedLM`, REML: fitness ~ method "
    "with a random intercept per GA run; a pair fitted on its own robots, the "
    "interaction on all four methods; Wald t on runs − methods df). With as many "
    "robots in every run the two share estimate and standard error; they differ in the "
    "df: the mixed model assumes one run-to-run spread for both methods, Welch does "
    "not. The robot-level tests above describe these runs only.\n\n"
)


def decision_table(t: NestedTables) -> pd.DataFrame:
    """One row per question: the answering test, its result and the mixed model's."""
    run = t.run_tests[t.run_tests["summary"] == "mean"].set_index("question")
    mixed = t.mixed.set_index("question")
    rows = []
    for name, _ in nested.questions():
        if name not in run.index:
            continue
        r = run.loc[name]
        row = {"question": name, "answered by": "Welch t on run means",
               "runs": r["runs"], "estimate [95 % CI]": fmt_ci(r["estimate"], r["ci_low"],
                                                               r["ci_high"]),
               "p_holm": r["p_holm"], "decision": _decision(name, r)}
        if name in mixed.index:
            m = mixed.loc[name]
            row["mixed model [95 % CI]"] = fmt_ci(m["estimate"], m["ci_low"], m["ci_high"])
            row["mixed p_holm"] = m["p_holm"]
            row["mixed decision"] = _decision(name, m)
        rows.append(row)
    return pd.DataFrame(rows)


def _decision(name: str, row: pd.Series) -> str:
    """``"E+L > R+L"`` when the test rejects, else ``"not decided"``."""
    if not bool(row["reject"]):
        return "not decided"
    sign = ">" if row["estimate"] > 0 else "<"
    if name == nested.INTERACTION_NAME:
        return f"interaction {sign} 0"
    a, _, b = name.partition(" vs ")
    return f"{a} {sign} {b}"


def nested_markdown(t: NestedTables) -> str:
    """The run-level sections as Markdown."""
    notes = "".join(f"- {n}\n" for n in t.notes) + ("\n" if t.notes else "")
    parts = ["\n## Runs as the unit\n\n", UNIT_NOTE, notes,
             "### Decision per question\n\n", markdown_table(decision_table(t)),
             "\n### Per method, runs as the unit\n\n",
             "Mean over runs of each run's summary, with a t interval over runs "
             "(`best`: the run's best robot; `final_population_mean`: the mean of its "
             "population after its last robot).\n\n",
             markdown_table(_means_wide(t.means)),
             "\n### Run-level tests of every run summary\n\n",
             "Welch t on one value per run; Holm over the three pairs per summary.\n\n",
             markdown_table(t.run_tests),
             "\n### Mixed model\n\n", markdown_table(t.mixed),
             "\n### Variance components\n\n",
             "Per method: robot-to-robot (`sd_within`) and run-to-run (`sd_between`, the "
             "run effect) standard deviations, one-way random-effects ANOVA.\n\n",
             markdown_table(t.components),
             "\n### Per-run summaries\n\n", markdown_table(t.runs)]
    if t.power is not None:
        parts += ["\n### Power: GA seeds needed\n\n", power_sentence(t.power),
                  markdown_table(t.power)]
    return "".join(parts)


def _means_wide(means: pd.DataFrame) -> pd.DataFrame:
    """Methods as rows, each run summary as ``estimate [CI]``."""
    cells = means.assign(cell=[fmt_ci(r.estimate, r.ci_low, r.ci_high)
                               for r in means.itertuples()])
    wide = cells.pivot(index="method", columns="summary", values="cell")
    wide = wide[[s for s in nested.RUN_SUMMARIES if s in wide.columns]]
    runs = means.drop_duplicates("method").set_index("method")["runs"]
    wide.insert(0, "runs", runs)
    return wide.loc[method_order(wide.index)].reset_index()


def power_sentence(table: pd.DataFrame) -> str:
    """How the seeds were computed, and the headline numbers."""
    first = table.iloc[0]
    half = table[np.isclose(table["delta"], first["delta"] / 2)
                 & (table["robots_per_run"] == first["robots_per_run"])]
    smaller = ("" if half.empty else f" Half that difference would need "
               f"{int(half['seeds'].iloc[0])} seeds per method.")
    return (
        f"GA seeds per method for Welch's test on run means to detect "
        f"{first['pair']} = {fmt_number(first['delta'])} (the observed difference) with "
        f"80 % power, planned at α = 0.05 / 3 (Holm over the three pairs: the level of "
        f"its first step, which holds whatever the other pairs do): **"
        f"{int(first['seeds'])} seeds per method** at {int(first['robots_per_run'])} robots "
        f"per run.{smaller} Method: each method's run-mean variance from its variance "
        "components (`sd_between² + sd_within² / robots_per_run`), the closed form of "
        "statsmodels' `TTestIndPower` on the run-level effect size (`seeds_closed_form`), "
        "then raised until a simulation of Welch's test (4,000 studies per candidate, "
        "normal run means, each method's own variance) reaches 80 % too (`seeds`): the "
        "methods' run-level spreads differ, which the closed form's pooled variance "
        "ignores. The spreads are estimated from the runs at hand, a few per method, so "
        "these numbers are rough.\n\n"
    )
