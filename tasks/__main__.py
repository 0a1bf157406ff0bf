"""``python -m skeleton_mamba.tasks`` is ``sm``."""

import sys

from skeleton_mamba.tasks.training.cli import main

sys.exit(main())
