"""``python -m analysis.ablation RUN... --out DIR``: the ablation report
(:mod:`analysis.ablation.report`)."""

import sys

from analysis.ablation.report import main

if __name__ == "__main__":
    sys.exit(main())
