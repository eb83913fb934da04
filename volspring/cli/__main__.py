"""``python -m volspring.cli``: the same as the ``volspring-sim`` command."""

import sys

from volspring.cli import main

if __name__ == "__main__":  # imported (by a test that imports every module), it does nothing
    sys.exit(main())
