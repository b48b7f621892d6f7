"""``python -m vrsync.mujoco``: see :mod:`vrsync.mujoco.cli`."""

import sys

from .cli import main

sys.exit(main())
