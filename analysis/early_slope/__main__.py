"""``python -m analysis.early_slope RUN... --out DIR``: the early-slope report
(``analysis.early_slope_report``)."""

import sys

from analysis.early_slope_report import main

sys.exit(main())
