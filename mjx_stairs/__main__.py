"""python -m mjx_stairs == mjx-stairs."""

import sys

from mjx_stairs.cli import main

sys.exit(main())
