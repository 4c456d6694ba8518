"""``python -m core`` is the ``pdr`` command."""

import sys

from core.cli import main

sys.exit(main())
