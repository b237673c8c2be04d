"""Sphinx configuration of cfcontact's documentation.

Build (no network needed; Debian's Sphinx, MyST parser and Read-the-Docs theme, installed by
scripts/install.sh):

    .venv/bin/python -m sphinx -W --keep-going -b html docs build/docs

The build runs the demos for the gallery (docs/_ext/cfcontact_docs.py): about a minute.
``CFCONTACT_DOCS_GALLERY=0`` skips them for quick edits of the text.
"""

import os
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
sys.path.insert(0, ROOT)  # the cfcontact of this checkout, also when it is not installed
sys.path.insert(0, os.path.join(HERE, "_ext"))

import cfcontact  # noqa: E402

project = "cfcontact"
author = "the cfcontact authors"
copyright = "the cfcontact authors"
version = release = cfcontact.__version__

extensions = [
    "myst_parser",
    "sphinx.ext.autodoc",
    "sphinx.ext.mathjax",
    "cfcontact_docs",
]
source_suffix = {".rst": "restructuredtext", ".md": "markdown"}
root_doc = master_doc = "index"
exclude_patterns = ["_build", "_ext", "img", "Thumbs.db", ".DS_Store"]
templates_path = []
language = "en"

# MyST: $...$ and $$...$$ math, amsmath environments (equations tagged with the paper's numbers),
# ::: fences, and anchors for headings down to ### (links like cli.md#output-folder).
myst_enable_extensions = ["dollarmath", "amsmath", "colon_fence", "deflist"]
myst_heading_anchors = 3

# autodoc: the docstrings as written; signatures with their annotations.
autodoc_member_order = "bysource"
autodoc_typehints = "signature"
autodoc_default_options = {"members": True}
autoclass_content = "both"
# The docstrings are plain text: "name : description" entries under "Parameters" / "Returns"
# headers with dashed underlines.  cfcontact_docs renders them as definition lists under rubrics
# (autodoc-process-docstring), without changing their words.

# HTML: the Read-the-Docs theme from Debian (no download).
html_theme = "sphinx_rtd_theme"
html_theme_options = {"navigation_depth": 3, "collapse_navigation": False}
html_title = f"cfcontact {release}"
html_static_path = []
html_show_sourcelink = True
html_copy_source = True

# Math: Debian's MathJax 2 (libjs-mathjax, installed by scripts/install.sh) when it is there, so
# that the formulas render offline; if the page is opened where that file is missing, the
# script's onerror loads the same MathJax version from its public CDN instead.  Only the math
# nodes are typeset (tex2jax processClass), never code.
LOCAL_MATHJAX = "/usr/share/javascript/mathjax/MathJax.js"
CDN_MATHJAX = "https://cdn.jsdelivr.net/npm/mathjax@2.7.9/MathJax.js"
if os.path.isfile(LOCAL_MATHJAX):
    mathjax_path = f"file://{LOCAL_MATHJAX}?config=TeX-AMS_CHTML"
else:
    mathjax_path = f"{CDN_MATHJAX}?config=TeX-AMS_CHTML"
mathjax_options = {
    "onerror": ("var s = document.createElement('script'); "
                f"s.src = '{CDN_MATHJAX}?config=TeX-AMS_CHTML'; document.head.appendChild(s);"),
}
mathjax2_config = {
    "tex2jax": {"processClass": "math", "ignoreClass": "document",
                "inlineMath": [["\\(", "\\)"]], "displayMath": [["\\[", "\\]"]]},
    "TeX": {"equationNumbers": {"autoNumber": "none"}},
}
mathjax3_config = None
