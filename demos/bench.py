"""Benchmarks of cfcontact's path following: a runnable wrapper of :mod:`cfcontact.bench`
(the same as ``cfcontact bench``; see docs/bench.md for measured numbers).

Run:  .venv/bin/python demos/bench.py [--quick] [--sizes 1e4,1.2e5,1e6] [--skip-large]
      [--output DIR] [--part A|B|AB] [--timeout S]
"""

import os
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
if ROOT not in sys.path:
    sys.path.insert(0, ROOT)

from cfcontact.bench import main  # noqa: E402

if __name__ == "__main__":
    sys.exit(main())
