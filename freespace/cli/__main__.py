"""``python -m freespace.cli``: the ``freespace`` command."""

import sys

from freespace.cli import main

sys.exit(main())
