"""``python -m analysis.early_slope RUN... --out DIR``: the early-slope report
(:mod:`analysis.early_slope.report`)."""

import sys

from analysis.early_slope.report import main

if __name__ == "__main__":
    sys.exit(main())
