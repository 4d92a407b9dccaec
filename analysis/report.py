"""``python -m analysis.report RUN... --out DIR``: the ablation report, as users have
typed it; the study lives in :mod:`analysis.ablation`."""

import sys

from analysis.ablation.report import main

if __name__ == "__main__":
    sys.exit(main())
