"""``python -m gisroads.cli``: the ``gisroads`` command."""
import sys

from .app import main

sys.exit(main())
