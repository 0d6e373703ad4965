"""``python -m pneubayes.cli``: the ``pneubayes`` command."""

import sys

from pneubayes.cli import main

sys.exit(main())
