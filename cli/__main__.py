"""``python -m eosp.cli`` = the ``eosp`` command."""

import sys

from eosp.cli import main

sys.exit(main())
