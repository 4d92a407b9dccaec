"""The ablation (paper §8): R+R, R+L, E+R and E+L, and the fifth arm E+L+I.

Does evolving structures pay off only when behaviours are learned? The study in one
place:

* :mod:`analysis.ablation.report`: the study's computation (``ablation_tables``), its
  writer (``write_report``: ``report.md``, CSVs and the paper's figures) and its command
  line, ``python -m analysis.report RUN... --out DIR`` (or ``python -m analysis
  ablation ...``);
* :mod:`analysis.ablation.robot_level`: per-method summaries, rank tests and contrasts with
  the robot as the unit;
* :mod:`analysis.ablation.nested` and :mod:`analysis.ablation.nested_report`: the same
  questions with the GA run as the unit (Welch on run means, a mixed model), and their
  sections of the report;
* :mod:`analysis.ablation.power`: the GA seeds a run-level test needs,
  ``python -m analysis.power RUN...``.

The notebook ``analysis/ablation.pct.py`` (paired with ``ablation.ipynb``) runs the
report's steps cell by cell.
"""
