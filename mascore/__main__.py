"""Entry point of ``python -m mascore`` and the ``mascore`` console script."""

import sys

from .reproduce import main

if __name__ == "__main__":
    sys.exit(main())
