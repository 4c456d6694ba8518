"""``python -m desktop`` is the ``pdr`` command."""

import sys

from desktop.cli import main

sys.exit(main())
