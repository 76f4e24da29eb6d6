"""``python -m gyrocal.kit`` is the same as the ``gyrocal`` console script."""

import sys

from gyrocal.kit.cli import main

sys.exit(main())
