"""``python -m analysis.equal_cost --without RUN... --with RUN... --out DIR``: early
rejection at equal cost (:mod:`analysis.equal_cost.early_rejection`)."""

import sys

from analysis.equal_cost.early_rejection import main

if __name__ == "__main__":
    sys.exit(main())
