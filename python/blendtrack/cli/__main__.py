"""``python -m blendtrack.cli``: the ``blendtrack`` command."""

import sys

from blendtrack.cli import main

sys.exit(main())
