"""``python -m kit`` is the same as the ``gyrocal`` console script."""

import sys

from kit.cli import main

sys.exit(main())
