"""``python -m wavepaths``: the command line (:mod:`wavepaths.cli`)."""

import sys

from .cli import main

sys.exit(main())
