"""Sphinx extension of cfcontact's documentation: generated content, no committed copies.

* ``case-reference`` directive: the case-file reference, ``cfcontact.case.reference_text()``
  (what ``cfcontact schema`` prints), rendered at build time: the schema is its one source.
* Docstrings: cfcontact's docstrings are plain text, with ``name : description`` entries
  (continued on indented lines) under ``Parameters`` / ``Returns`` headers underlined with
  dashes.  :func:`docstring_lines` renders them as reStructuredText -- entries as definition
  lists, headers as rubrics, ``|x|`` as text, not substitutions -- without changing a word
  (``autodoc-process-docstring``).
* The gallery: when the build starts, the demos run (``demos/main.py``, ``demos/pictures.py``,
  reduced validation demos, the tutorial's code blocks) and write their pictures and printed
  output into the build directory (``<doctreedir>/gallery/<job>/``, beside the doctrees).
  ``gallery-figure JOB/FILE`` shows a picture from there, ``gallery-output JOB/FILE`` a text
  file (a demo's printed table, the output of a tutorial block).  Nothing in the gallery comes
  from a committed image.  A job that fails runs once more (its first try's output is kept as
  ``try1-stdout.txt``, ``try1-stderr.txt``); when it fails again the build fails with the end of
  what it printed on stderr and stdout.

Environment:

* ``CFCONTACT_DOCS_GALLERY=0``: run no demo (figures and outputs become a one-line note; for
  quick edits of the text), ``force``: rerun every job even if its outputs are up to date.
  By default a job runs again only when what it depends on (the package, this file, its own
  script or page) changed since its last run into this build directory.
* ``CFCONTACT_DOCS_JOBS``: how many demos run at once (default 2).
"""

from __future__ import annotations

import hashlib
import os
import re
import shutil
import subprocess
import sys
import time

from docutils import nodes
from docutils.parsers.rst import Directive, directives
from sphinx.errors import ExtensionError
from sphinx.util import logging

log = logging.getLogger(__name__)

HERE = os.path.dirname(os.path.abspath(__file__))
DOCS = os.path.dirname(HERE)
ROOT = os.path.dirname(DOCS)

#: how often a failing job runs before the build fails (see run_gallery)
MAX_TRIES = 2

#: job -> (command; {out} is the job's output folder; what it is; the files it depends on besides
#: the package).  Commands run in the repository root with this Python.  Reduced versions are
#: said so on the pages that show them.
JOBS = {
    "demo": (["demos/main.py", "--output", "{out}"],
             "the main demo as ./demo.sh runs it (three paths, n = 1320, pictures)", ("demos/main.py",)),
    "variants": (["demos/pictures.py", "-o", "{out}"],
                 "one solved point of every example case (the geometry variants)",
                 ("demos/pictures.py", "demos/cases")),
    "hertz": (["demos/hertz.py", "--quick", "-o", "{out}"],
              "Hertz validation on the two coarse meshes (--quick)", ("demos/hertz.py",)),
    "mindlin": (["demos/mindlin.py", "--size", "0.02", "--nx", "30", "-o", "{out}"],
                "Cattaneo-Mindlin validation on coarse meshes (h = 0.02, nx = 30)",
                ("demos/mindlin.py", "demos/hertz.py")),
    "critical": (["demos/critical_friction.py", "--quick"],
                 "critical friction of the two-block models on coarse meshes (--quick)",
                 ("demos/critical_friction.py",)),
    "friction_map": (["demos/friction_map.py", "--quick", "--output", "{out}"],
                     "the (alpha, F) map of the main demo's load path on 40 x 40 grids (--quick)",
                     ("demos/friction_map.py",)),
    "tutorial": (["docs/_ext/run_blocks.py", "docs/tutorial.md", "{out}"],
                 "the Python blocks of the tutorial, in order", ("docs/tutorial.md", "docs/_ext/run_blocks.py")),
}

#: what every job depends on: a change there runs them all again
COMMON_SOURCES = ("cfcontact", "docs/_ext/cfcontact_docs.py")


# ------------------------------------------------------------------ docstrings
#: "name : text", "name: text", "a, b : text" at the start of a line (identifiers only, at most
#: one space before the colon: aligned tables like "open   : -a >= 0" stay as they are)
_ENTRY = re.compile(r"^(?P<ind>[ ]*)(?P<names>\*{0,2}[A-Za-z_]\w*(?:[ ]*,[ ]*\*{0,2}[A-Za-z_]\w*)*)[ ]?:[ ]+(?P<text>\S.*)$")
_HEADERS = ("Parameters", "Other Parameters", "Returns", "Yields", "Raises", "Warns", "Attributes",
            "Notes", "Examples", "See Also", "References")
#: |x| (an absolute value, no spaces), which reStructuredText would take for a substitution
_BARS = re.compile(r"(?<![|\\`])\|([^|\s`]{1,20})\|(?![|_`])")


def _indent(line: str) -> int:
    return len(line) - len(line.lstrip(" "))


def _entry_block(block: list) -> list:
    """A block (no blank line) of ``name : text`` entries with indented continuations as a
    definition list, and prose after two or more entries as a paragraph after it; any other
    block unchanged."""
    base = _indent(block[0])
    if not _ENTRY.match(block[0]):
        return block
    entries, rest = [], []
    for k, line in enumerate(block):
        if _indent(line) > base and entries:
            entries[-1][1].append(line)
        elif _indent(line) == base and _ENTRY.match(line):
            entries.append((_ENTRY.match(line), []))
        elif _indent(line) == base and len(entries) >= 2:
            rest = [""] + block[k:]
            break
        else:
            return block
    out = []
    pad = " " * base
    for m, cont in entries:
        out.append(f"{pad}{m.group('names')}")
        out.append(f"{pad}    {m.group('text')}")
        if cont:
            cut = min(_indent(c) for c in cont)
            out.extend(f"{pad}    {c[cut:]}" for c in cont)
    return out + rest


def docstring_lines(lines: list) -> list:
    """cfcontact's plain-text docstring lines as reStructuredText (see the module docstring)."""
    lines = [_BARS.sub(r"\\|\1\\|", ln) for ln in lines]
    out, i = [], 0
    while i < len(lines):  # "Parameters" + "----------" -> a rubric
        ln = lines[i]
        nxt = lines[i + 1] if i + 1 < len(lines) else ""
        if ln.strip() in _HEADERS and set(nxt.strip()) == {"-"} and _indent(nxt) == _indent(ln):
            out += [f"{' ' * _indent(ln)}.. rubric:: {ln.strip()}", ""]
            i += 2
            continue
        out.append(ln)
        i += 1
    result, block = [], []
    for ln in out + [""]:
        if ln.strip():
            block.append(ln)
            continue
        if block:
            result += _entry_block(block)
            block = []
        result.append(ln)
    return result[:-1]


def _process_docstring(app, what, name, obj, options, lines):
    lines[:] = docstring_lines(lines)


# ------------------------------------------------------------------ gallery
def _sources_digest(sources) -> str:
    """A hash of the Python in use and of the files under ``sources`` (paths from the root)."""
    h = hashlib.sha256(sys.executable.encode())
    for src in sources:
        full = os.path.join(ROOT, *src.split("/"))
        files = [full] if os.path.isfile(full) else sorted(
            os.path.join(d, f) for d, _, fs in os.walk(full) if "__pycache__" not in d
            for f in fs if not f.endswith((".pyc", ".msh")) and "_out" not in d)
        for fn in files:
            h.update(os.path.relpath(fn, ROOT).encode())
            with open(fn, "rb") as fh:
                h.update(hashlib.sha256(fh.read()).digest())
    return h.hexdigest()


def _job_env() -> dict:
    env = dict(os.environ)
    env["PYTHONPATH"] = ROOT + (os.pathsep + env["PYTHONPATH"] if env.get("PYTHONPATH") else "")
    env.setdefault("OPENBLAS_NUM_THREADS", "1")
    env.setdefault("OMP_NUM_THREADS", "1")
    env["MPLBACKEND"] = "Agg"
    env["PYTHONUNBUFFERED"] = "1"  # a job that dies still leaves what it printed
    env["PYTHONFAULTHANDLER"] = "1"
    return env


def _tail(fn: str, lines: int = 30) -> str:
    try:
        with open(fn, errors="replace") as fh:
            return "".join(fh.readlines()[-lines:])
    except OSError:
        return ""


def _failure(name, cmd, out, returncode, seconds) -> str:
    """What a failed job left: its exit status, time, and the ends of its stderr and stdout."""
    err, std = _tail(os.path.join(out, "stderr.txt")), _tail(os.path.join(out, "stdout.txt"), 10)
    return (f"{name} ({' '.join(cmd)}) exited with {returncode} after {seconds:.1f} s\n"
            f"--- end of its stderr ---\n{err or '(nothing on stderr)'}\n"
            f"--- end of its stdout ---\n{std or '(nothing on stdout)'}")


def run_gallery(stage: str, mode: str = "1", parallel: int = 2) -> None:
    """Run the jobs whose outputs in ``stage`` are missing or stale (all of them with ``force``)."""
    todo = []
    for name, (cmd, what, deps) in JOBS.items():
        out = os.path.join(stage, name)
        stamp = os.path.join(out, ".stamp")
        digest = _sources_digest(COMMON_SOURCES + deps) + " " + " ".join(cmd)
        if mode != "force" and os.path.isfile(stamp):
            with open(stamp) as fh:
                if fh.read() == digest:
                    continue
        shutil.rmtree(out, ignore_errors=True)
        os.makedirs(out)
        todo.append((name, [sys.executable] + [a.format(out=out) for a in cmd], out, what, digest))
    if not todo:
        log.info("[gallery] up to date in %s", stage)
        return
    env = _job_env()
    running, failed = [], []
    tries = {}
    t_all = time.perf_counter()
    while todo or running:
        while todo and len(running) < max(1, parallel):
            name, cmd, out, what, digest = todo.pop(0)
            tries[name] = tries.get(name, 0) + 1
            log.info("[gallery] %s: %s", name, what)
            fo = open(os.path.join(out, "stdout.txt"), "w")
            fe = open(os.path.join(out, "stderr.txt"), "w")
            proc = subprocess.Popen(cmd, cwd=ROOT, env=env, stdout=fo, stderr=fe, stdin=subprocess.DEVNULL)
            running.append((name, cmd, out, what, proc, fo, fe, time.perf_counter(), digest))
        time.sleep(0.2)
        for item in list(running):
            name, cmd, out, what, proc, fo, fe, t0, digest = item
            if proc.poll() is None:
                continue
            running.remove(item)
            fo.close()
            fe.close()
            seconds = time.perf_counter() - t0
            if proc.returncode == 0:
                with open(os.path.join(out, ".stamp"), "w") as fh:
                    fh.write(digest)
                log.info("[gallery] %s done in %.1f s", name, seconds)
            elif tries[name] < MAX_TRIES:
                # A job has died early with exit status 1 and nothing on stderr, once in CI and
                # once in about sixty builds here (Debian 12; never under strace or an exit hook,
                # cause unknown): it runs once more, and the build fails only when it fails
                # again.  What the failed try left is kept beside the outputs (try<k>-*.txt).
                log.info("[gallery] %s failed, running it once more: %s", name,
                         _failure(name, cmd, out, proc.returncode, seconds))
                for stream in ("stdout", "stderr"):
                    os.replace(os.path.join(out, f"{stream}.txt"),
                               os.path.join(out, f"try{tries[name]}-{stream}.txt"))
                for entry in os.listdir(out):  # the next try starts from an empty folder
                    if not re.fullmatch(r"try\d+-(stdout|stderr)\.txt", entry):
                        full = os.path.join(out, entry)
                        if os.path.isdir(full):
                            shutil.rmtree(full)
                        else:
                            os.remove(full)
                todo.insert(0, (name, cmd, out, what, digest))
            else:
                failed.append(_failure(name, cmd, out, proc.returncode, seconds))
    if failed:
        raise ExtensionError("a gallery job failed: " + "\n".join(failed))
    log.info("[gallery] all jobs done in %.1f s", time.perf_counter() - t_all)


def _builder_inited(app):
    stage = os.path.join(app.doctreedir, "gallery")
    app.config.cfcontact_gallery_dir = stage
    mode = os.environ.get("CFCONTACT_DOCS_GALLERY", "1").strip().lower()
    if mode in ("0", "no", "off", "false"):
        log.info("[gallery] skipped (CFCONTACT_DOCS_GALLERY=%s)", mode)
        app.config.cfcontact_gallery_skip = True
        return
    app.config.cfcontact_gallery_skip = False
    os.makedirs(stage, exist_ok=True)
    run_gallery(stage, mode, int(os.environ.get("CFCONTACT_DOCS_JOBS", "2")))


class _GalleryDirective(Directive):
    required_arguments = 1

    def _file(self):
        """(absolute path of the gallery file, or None when the gallery is skipped)."""
        config = self.state.document.settings.env.config
        if config.cfcontact_gallery_skip:
            return None
        rel = self.arguments[0]
        if rel.split("/", 1)[0] not in JOBS:
            raise self.error(f"{self.name}: unknown gallery job in {rel!r} (jobs: {', '.join(JOBS)})")
        full = os.path.join(config.cfcontact_gallery_dir, *rel.split("/"))
        if not os.path.isfile(full):
            raise self.error(f"{self.name}: {rel} was not produced by its job "
                             f"(see {os.path.dirname(full)}/stderr.txt)")
        return full

    def _skipped(self):
        return [nodes.paragraph(text=f"[{self.arguments[0]}: not generated in this build, "
                                     "CFCONTACT_DOCS_GALLERY=0]")]


class GalleryFigure(_GalleryDirective):
    """A picture a gallery job wrote: ``gallery-figure JOB/FILE.png``; content = caption."""

    has_content = True
    option_spec = {"width": directives.length_or_percentage_or_unitless, "alt": directives.unchanged}

    def run(self):
        full = self._file()
        if full is None:
            return self._skipped()
        env = self.state.document.settings.env
        docdir = os.path.dirname(env.doc2path(env.docname))
        image = nodes.image(uri=os.path.relpath(full, docdir), alt=self.options.get("alt", self.arguments[0]))
        if "width" in self.options:
            image["width"] = self.options["width"]
        figure = nodes.figure("", image)
        if self.content:
            holder = nodes.Element()
            self.state.nested_parse(self.content, self.content_offset, holder)
            first = holder[0] if len(holder) and isinstance(holder[0], nodes.paragraph) else None
            if first is not None:
                figure += nodes.caption(first.rawsource, "", *first.children)
                figure += nodes.legend("", *holder[1:]) if len(holder) > 1 else []
        return [figure]


class GalleryOutput(_GalleryDirective):
    """A text file a gallery job wrote (its printed output): ``gallery-output JOB/FILE``.

    ``:start-at: TEXT`` starts at the first line containing TEXT, ``:end-before: TEXT`` stops
    before the next line containing TEXT."""

    option_spec = {"start-at": directives.unchanged, "end-before": directives.unchanged,
                   "language": directives.unchanged}

    def run(self):
        full = self._file()
        if full is None:
            return self._skipped()
        with open(full, encoding="utf-8") as fh:
            lines = fh.read().splitlines()
        if "start-at" in self.options:
            hits = [i for i, ln in enumerate(lines) if self.options["start-at"] in ln]
            if not hits:
                raise self.error(f"{self.arguments[0]}: no line contains {self.options['start-at']!r}")
            lines = lines[hits[0]:]
        if "end-before" in self.options:
            hits = [i for i, ln in enumerate(lines) if i and self.options["end-before"] in ln]
            lines = lines[:hits[0]] if hits else lines
        text = "\n".join(lines).rstrip() or "(no output)"
        block = nodes.literal_block(text, text)
        block["language"] = self.options.get("language", "text")
        return [block]


class CaseReference(Directive):
    """The case-file reference, generated from the schema (``cfcontact schema``)."""

    def run(self):
        from cfcontact.case import reference_text

        text = reference_text().rstrip("\n")
        block = nodes.literal_block(text, text)
        block["language"] = "toml"
        return [block]


def setup(app):
    app.add_config_value("cfcontact_gallery_dir", "", "")
    app.add_config_value("cfcontact_gallery_skip", False, "")
    app.connect("builder-inited", _builder_inited)
    app.connect("autodoc-process-docstring", _process_docstring)
    app.add_directive("gallery-figure", GalleryFigure)
    app.add_directive("gallery-output", GalleryOutput)
    app.add_directive("case-reference", CaseReference)
    return {"version": "1", "parallel_read_safe": True, "parallel_write_safe": True}
