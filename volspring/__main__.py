"""``python -m volspring``: the same as the ``volspring`` command (:mod:`volspring.command`)."""

import sys

from volspring.command import main

if __name__ == "__main__":  # imported (by a test that imports every module), it does nothing
    sys.exit(main())
