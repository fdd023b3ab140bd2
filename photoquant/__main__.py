"""``python -m photoquant``."""

import sys

from photoquant.cli import main

sys.exit(main())
