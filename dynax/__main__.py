"""`python -m dynax ...` runs the `dynax` console script."""

import sys

from ._cli._main import main

if __name__ == "__main__":
    sys.exit(main())
