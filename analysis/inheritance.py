"""``python -m analysis.inheritance RUNS... --out DIR``: policy inheritance at equal cost,
as users have typed it; the study lives in :mod:`analysis.equal_cost.inheritance`."""

import sys

from analysis.equal_cost.inheritance import main

if __name__ == "__main__":
    sys.exit(main())
