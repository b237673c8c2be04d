"""Run the Python code blocks of a Markdown page, in order, in one namespace.

    python docs/_ext/run_blocks.py docs/tutorial.md OUTDIR

Every fenced block opened by a line ```` ```python ```` is executed, in the order of the page,
with OUTDIR as the working directory (so the files the page writes land there).  What block k
(counted from 1) prints goes to ``OUTDIR/block-<k>.txt``.  A block that raises stops the run with
the block's number and source on stderr and exit status 1.

The documentation build runs the tutorial this way (docs/_ext/cfcontact_docs.py), so the
tutorial's code is checked on every build and its pictures and printed output are the real ones.
"""

from __future__ import annotations

import contextlib
import io
import os
import re
import sys
import traceback

FENCE = re.compile(r"^```python[ \t]*\n(.*?)^```[ \t]*$", re.S | re.M)


def blocks(markdown: str) -> list[str]:
    """The sources of the ```python blocks of a Markdown text, in order."""
    return [m.group(1) for m in FENCE.finditer(markdown)]


def run(page: str, outdir: str) -> int:
    with open(page, encoding="utf-8") as fh:
        sources = blocks(fh.read())
    os.makedirs(outdir, exist_ok=True)
    os.chdir(outdir)
    namespace = {"__name__": "__main__"}
    for k, src in enumerate(sources, 1):
        out = io.StringIO()
        try:
            with contextlib.redirect_stdout(out):
                exec(compile(src, f"{os.path.basename(page)}, block {k}", "exec"), namespace)
        except BaseException:
            sys.stdout.write(out.getvalue())
            print(f"{page}: block {k} failed:\n{src}", file=sys.stderr)
            traceback.print_exc()
            return 1
        with open(f"block-{k}.txt", "w", encoding="utf-8") as fh:
            fh.write(out.getvalue())
    print(f"{page}: {len(sources)} blocks ran in {outdir}")
    return 0


if __name__ == "__main__":
    if len(sys.argv) != 3:
        sys.exit(__doc__)
    sys.exit(run(sys.argv[1], sys.argv[2]))
