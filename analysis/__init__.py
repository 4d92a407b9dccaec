"""Analysis of evo runs (SPEC section 7): it reads run directories and recordings and
never trains.

Each study is in one place, with one computation that returns its tables, one writer
and one command line (``python -m analysis <study> ...``; ``python -m analysis`` lists
them, and each study's module command works as well):

* :mod:`analysis.ablation`: R+R, R+L, E+R and E+L (paper §8) and the fifth arm E+L+I;
* :mod:`analysis.early_slope`: does the start of a learning curve predict fitness?
* :mod:`analysis.equal_cost`: a change to the GA against none at equal env steps, used
  for early rejection and for policy inheritance;
* the noise ceiling (:mod:`analysis.noise_ceiling`, :mod:`analysis.noise_study`,
  :mod:`analysis.noise_sweep`) and the designer comparison (:mod:`analysis.designer`),
  modules for now.

Shared by the studies, one each: the loader (:mod:`analysis.load`, the tables it fills,
:mod:`analysis.tables`, and the steady-state replay and cost traces,
:mod:`analysis.population`), intervals and tests (:mod:`analysis.stats`), figures
(:mod:`analysis.plots`), Markdown (:mod:`analysis.markdown`) and command lines
(:mod:`analysis.cli`); :mod:`analysis.synthetic` makes tables with a known answer for
tests.
"""
