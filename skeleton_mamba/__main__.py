"""``python -m skeleton_mamba`` is ``sm``."""

import sys

from skeleton_mamba.cli import main

sys.exit(main())
