"""``nnfmu`` / ``python -m nnfmu``: see :mod:`nnfmu.cli`."""

import sys

from nnfmu.cli import main

if __name__ == "__main__":
    sys.exit(main())
