"""``python -m analysis.power RUN...``: the GA seeds a run-level test needs, as users have
typed it; the code is :mod:`analysis.ablation.power`."""

import sys

from analysis.ablation.power import main

if __name__ == "__main__":
    sys.exit(main())
