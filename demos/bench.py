"""Benchmarks of cfcontact's path following: a runnable wrapper of :mod:`cfcontact.bench`
(the same as ``cfcontact bench``; see docs/bench.md for measured numbers).

Run:  .venv/bin/python demos/bench.py [--quick] [--sizes 1e4,1.2e5,1e6] [--skip-large]
      [--output DIR] [--part A|B|AB] [--timeout S]
"""

import sys

from cfcontact.bench import main

if __name__ == "__main__":
    sys.exit(main())
