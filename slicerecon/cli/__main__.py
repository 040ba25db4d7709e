"""``python -m slicerecon.cli``: the ``slicerecon`` command."""

import sys

from . import main

sys.exit(main())
