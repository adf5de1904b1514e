"""``python -m grisx`` runs the command line."""

import sys

from grisx.cli import main

sys.exit(main())
