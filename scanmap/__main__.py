"""`python -m scanmap` runs the command line."""

import sys

from scanmap.cli import main

sys.exit(main())
