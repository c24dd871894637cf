"""``python -m isoflow.cli``: the ``isoflow`` command."""

import sys

from . import main

sys.exit(main())
