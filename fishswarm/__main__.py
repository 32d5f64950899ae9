"""``python -m fishswarm``: the same as the ``fishswarm`` command."""

import sys

from fishswarm.cli import main

sys.exit(main())
