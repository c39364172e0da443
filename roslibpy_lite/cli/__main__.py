"""``python -m roslibpy_lite.cli``: the ``roslibpy-lite`` command."""

import sys

from . import main

sys.exit(main())
