"""``python -m cfcontact``: the command line (see :mod:`cfcontact.cli`)."""

import sys

from cfcontact.cli import main

sys.exit(main())
