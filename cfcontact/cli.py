"""Command line of cfcontact: ``cfcontact SUBCOMMAND ...`` (also ``python -m cfcontact``).

``run CASE.toml`` validates a case file (:mod:`cfcontact.case`; the format: ``cfcontact schema``
and docs/case-files.md), builds the model, traces the path and writes the output folder
(:mod:`cfcontact.run`: stop conditions, checkpoints, resume, atomic output).  ``plot``,
``render``, ``info`` (:mod:`cfcontact.report`) and ``export`` work on a saved path: a ``path/``
folder, a run's output folder, or a stopped run's ``<out>.partial/`` folder.  ``bench`` runs
:mod:`cfcontact.bench`.  This module is argparse, the terminal (progress line, Ctrl-C, messages)
and dispatch; the work is in the library.

Exit codes: 0 done (path traced, output written), 1 failure, 2 bad input (one message on
stderr, no output), 3 stopped before the end by a stop condition or the time limit
(resumable checkpoint left), 130 stopped by Ctrl-C (resumable checkpoint left).
"""

from __future__ import annotations

import argparse
import contextlib
import json
import logging
import math
import os
import re
import shlex
import signal
import sys
import threading
import time
import traceback
import warnings

from cfcontact.case import CaseError, check_size, load_case, parse_component, python_sigint, reference_text
from cfcontact.errors import CfcontactError, InputError
from cfcontact.interrupts import caused_by_interrupt
from cfcontact.options import ALPHA_LIMIT, MAX_FRICTION
from cfcontact.report import format_report, path_report, turned_back_text, unverified_alphas, unverified_text
from cfcontact.run import (
    DEFAULT_CHECKPOINT_EVERY,
    CaseRun,
    Runner,
    StopConditions,
    Stopped,
    default_alpha,
    load_saved_path,
    output_folder,
    parameter_label,
    resolve_saved,
    run_timings,
    saved_material,
)
from cfcontact.solution_path import parameter_name

EXIT_OK, EXIT_FAILURE, EXIT_INPUT, EXIT_STOPPED, EXIT_INTERRUPTED = 0, 1, 2, 3, 130
#: the outputs are written, but the path did not reach the end of its range (its status is one of
#: INCOMPLETE_STATUSES, or rows of a map could not be traced): a script must not take it for a
#: whole result
EXIT_INCOMPLETE = 4
INCOMPLETE_STATUSES = ("stuck", "cycling", "max_transitions", "max_steps")


# ============================================================ progress / logging
class _Progress:
    """A throttled one-line progress display on stderr (TTY: rewritten in place)."""

    def __init__(self, enabled, tty, interval=0.2):
        self.enabled, self.tty = enabled, tty
        self.interval = interval if tty else 1.0
        self.last = -1e9
        self.shown = False

    def update(self, text, force=False):
        if not self.enabled:
            return
        now = time.monotonic()
        if not force and now - self.last < self.interval:
            return
        self.last = now
        if self.tty:
            sys.stderr.write("\r\x1b[2K" + text)
            self.shown = True
        else:
            sys.stderr.write(text + "\n")
        sys.stderr.flush()

    def clear(self):
        if self.shown:
            sys.stderr.write("\r\x1b[2K")
            sys.stderr.flush()
            self.shown = False

    def done(self):
        if self.shown:
            sys.stderr.write("\n")
            sys.stderr.flush()
            self.shown = False


class _ProgressAwareHandler(logging.StreamHandler):
    """Log records on stderr that first clear the progress line."""

    progress = None

    def emit(self, record):
        if self.progress is not None:
            self.progress.clear()
        super().emit(record)


@contextlib.contextmanager
def _logging(level):
    """Configure the ``cfcontact`` logger for one command (the library itself only logs)."""
    logger = logging.getLogger("cfcontact")
    handler = _ProgressAwareHandler(sys.stderr)
    handler.setFormatter(logging.Formatter("%(levelname)s %(name)s: %(message)s"))
    old_level, old_prop = logger.level, logger.propagate
    logger.addHandler(handler)
    logger.setLevel(level)
    logger.propagate = False
    try:
        yield handler
    finally:
        logger.removeHandler(handler)
        logger.setLevel(old_level)
        logger.propagate = old_prop


#: The most frames of a rendered animation (each is one off-screen render)
MAX_FRAMES = 10000

#: "file:line: Category: message" -- the first line of a formatted Python warning
_WARNING_LINE = re.compile(r"^.*?:\d+: (\w+): (.*)$")


def _warning_text(category_name: str, message: str) -> str:
    """One line for a Python warning: its message (the category's name too unless it is one of
    cfcontact's own, e.g. PairingWarning)."""
    first = str(message).strip().splitlines()[0] if str(message).strip() else ""
    return first if category_name == "PairingWarning" else f"{category_name}: {first}"


class _PyWarningsHandler(logging.Handler):
    """Python warnings routed into logging (dolfinx's import calls ``logging.captureWarnings``:
    the "py.warnings" logger then gets "file:line: Category: message" and the source line) as
    one line each, like the command's other warnings."""

    def __init__(self, show):
        super().__init__()
        self.show = show

    def emit(self, record):
        text = record.getMessage().strip()
        match = _WARNING_LINE.match(text.splitlines()[0] if text else "")
        self.show(_warning_text(*match.groups()) if match else text)


@contextlib.contextmanager
def _python_warnings(args):
    """During a command, every Python warning is one line "cfcontact: warning: ..." on stderr
    (none with --quiet), not the interpreter's two lines with the source file and line; both
    routes are caught, the interpreter's own and logging's once dolfinx has been imported."""
    def show(text):
        if not getattr(args, "quiet", False):
            progress = _ProgressAwareHandler.progress
            if progress is not None:
                progress.clear()
            print(f"cfcontact: warning: {text}", file=sys.stderr, flush=True)

    def showwarning(message, category, filename, lineno, file=None, line=None):
        show(_warning_text(category.__name__, message))

    logger = logging.getLogger("py.warnings")
    handler = _PyWarningsHandler(show)
    saved = warnings.showwarning, logger.propagate
    warnings.showwarning = showwarning
    logger.addHandler(handler)
    logger.propagate = False
    try:
        yield
    finally:
        logger.removeHandler(handler)
        logger.propagate = saved[1]
        if warnings.showwarning is showwarning:
            warnings.showwarning = saved[0]


def output_file(out, flag="-o") -> str:
    """``out`` as a file to write (CaseError naming ``flag``: an existing folder of that name, a
    parent that is a file or cannot be created); its folder is created."""
    if os.path.isdir(out):
        raise CaseError(f"{flag}: {out!r} is a folder, not a file")
    output_folder(os.path.dirname(os.path.abspath(out)), repr(out), flag)
    return out


def _no_empty_names(args):
    """CaseError for an empty output name (``-o ""``): it would otherwise read as no -o at all and
    the default be written without a word."""
    for attr, flag in (("output", "-o/--output"), ("animation", "--animation")):
        if getattr(args, attr, None) == "":
            raise CaseError(f"{flag}: the name is empty; give a file or folder name (or leave {flag.split('/')[0]} "
                            "out for the default)")


def _say(args, *text):
    if not getattr(args, "quiet", False):
        print(*text, flush=True)


def _warn(args, text):
    if not getattr(args, "quiet", False):
        print(f"cfcontact: warning: {text}", file=sys.stderr, flush=True)


def _note_from_handler(text):
    """Write ``text`` to stderr from a signal handler: on the file descriptor, not through
    sys.stderr, whose buffered writer may be in the middle of a write (a log line) when the signal
    comes -- Python then raises "reentrant call" inside logging, which prints a traceback.  A
    stream without a descriptor (a test's capture) is written as usual."""
    try:
        fd = sys.stderr.fileno()
    except (AttributeError, OSError, ValueError):  # (io.UnsupportedOperation: a capture object)
        print(text, end="", file=sys.stderr, flush=True)
        return
    os.write(fd, text.encode(getattr(sys.stderr, "encoding", None) or "utf-8", "replace"))


@contextlib.contextmanager
def _sigint(runner, progress, note="stopping at the next point (checkpoint follows); Ctrl-C again to abort"):
    """First Ctrl-C: stop cleanly at the next accepted point (while the outputs are written: before
    the next file; a Ctrl-C raised inside a library such as VTK could be lost there); second:
    KeyboardInterrupt."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def handler(signum, frame):
        if runner.interrupted:
            signal.signal(signal.SIGINT, signal.default_int_handler)
            raise KeyboardInterrupt
        runner.interrupt()
        erase = "\r\x1b[2K" if progress.shown else ""
        progress.shown = False
        _note_from_handler(f"{erase}\ncfcontact: {note}\n")

    old = signal.signal(signal.SIGINT, handler)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, old)


_PROGRAM = {"main": False}  # True when main() runs as the program (argv from sys.argv)


def _default_sigpipe():
    """Importing PETSc installs a SIGPIPE handler that aborts MPI when stdout is a closed pipe
    (``cfcontact info ... | head``); as a program, die quietly like other command-line tools."""
    if _PROGRAM["main"] and hasattr(signal, "SIGPIPE") and threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGPIPE, signal.SIG_DFL)


# ============================================================ run
@contextlib.contextmanager
def _sigint_ignored():
    """Ctrl-C is ignored for a moment (cleaning up after an interrupt: one message, no traceback)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    old = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, old)


def cmd_run(args):
    t_start = time.monotonic()
    case = load_case(args.case)
    python_sigint()  # gmsh may have been imported meanwhile
    stops = StopConditions(time_limit=args.time_limit, stop_after_folds=args.stop_after_folds,
                           stop_after_transitions=args.stop_after_transitions, stop_at_alpha=args.stop_at_alpha,
                           checkpoint_every=args.checkpoint_every)
    if args.stop_at_alpha is not None:
        p = case["path"]
        friction = p.get("parameter") == "friction"
        a0, a1 = (p["friction_start"], p["friction_end"]) if friction else (p["alpha_start"], p["alpha_end"])
        if not (min(a0, a1) <= args.stop_at_alpha <= max(a0, a1)) or args.stop_at_alpha == a0:
            raise CaseError(f"--stop-at-alpha {args.stop_at_alpha:g}: the path runs from "
                            f"{parameter_name(p.get('parameter'))} = {a0:g} to {a1:g}; give a value after its start, "
                            f"within that range")
    check_size(case, allow_large=args.allow_large)
    for text in case.get("_warnings", ()):
        _warn(args, text)
    with CaseRun(case, args.output, force=args.force, resume=args.resume, warn=lambda text: _warn(args, text)) as run:
        return _run_case(args, case, run, stops, t_start)


def _run_case(args, case, run, stops, t_start):
    progress = _Progress(enabled=not args.quiet and (args.verbose or sys.stderr.isatty()), tty=sys.stderr.isatty())
    runner = Runner(stops, progress, t_start)
    _ProgressAwareHandler.progress = progress
    again = shlex.quote(args.case) + (f" --output {shlex.quote(args.output)}" if args.output else "")
    try:
        run.start()
        if run.traced:
            _say(args, f"cfcontact: the path of {os.path.basename(case['_file'])} is traced (checkpoint in "
                       f"{run.partial}); writing the outputs")
            path, system = run.resume["path"], None
        else:
            _say(args, f"cfcontact: building the model of {os.path.basename(case['_file'])}")
            system = run.build()
            with _sigint(runner, progress):
                path = run.trace(system, runner)
        _default_sigpipe()
        unverified = unverified_alphas(path.events)
        if path.status != "completed":
            _warn(args, f"the path ended with status {path.status!r} (see the events in summary.json / info)")
        elif path.turned_back():
            _warn(args, turned_back_text(path.reach(), path.alpha_start, getattr(path, "parameter", "alpha"),
                                         unverified=bool(unverified)))
        if unverified:
            _warn(args, unverified_text(unverified))
        if not run.traced and runner.reason is not None:  # a stop after the main run: the tree or the tries
            left = path.stats.get("untried_alternatives")
            _warn(args, f"{runner.reason} after the main run: " + (
                f"the tree is incomplete, {left} alternative(s) not followed" if left else
                "the backtracking was cut short") + " (see the events in summary.json / info)")
        runner.interrupted = False  # (a Ctrl-C while tracing stopped the trace: Stopped above)
        with _sigint(runner, progress, "stopping before the next output (the checkpoint is kept); Ctrl-C again to "
                                       "abort"):
            files = run.finish(path, lambda text: _warn(args, text), system, interrupted=lambda: runner.interrupted)
    except Stopped as stop:
        progress.done()
        ck = os.path.join(run.partial, "checkpoint")
        if not stop.checkpoint:  # stopped before the path had a point: nothing to keep
            run.abandon(interrupted=stop.interrupted)
            _say(args, f"cfcontact: {stop.reason}; the path had no point yet, nothing to resume: run again to start "
                       f"over (cfcontact run {again})")
        elif stop.resumable:
            _say(args, f"cfcontact: {stop.reason}; checkpoint in {ck}\ncontinue with: cfcontact run --resume {again}")
        else:
            _say(args, f"cfcontact: {stop.reason}; the partial path is in {ck} (cfcontact info {run.partial}); it "
                       f"left no resume state: start over with cfcontact run --force {again}")
        return EXIT_INTERRUPTED if stop.interrupted else EXIT_STOPPED
    except BaseException as exc:
        # a Ctrl-C, or one that a library re-raised as another error (not SystemExit and its kin)
        if isinstance(exc, (KeyboardInterrupt, Exception)) and caused_by_interrupt(exc):
            with _sigint_ignored():
                progress.done()
                if run.abandon(interrupted=True):
                    print(f"cfcontact run: interrupted; the checkpoint in {run.partial} is kept: continue with: "
                          f"cfcontact run --resume {again}", file=sys.stderr, flush=True)
                else:
                    print("cfcontact run: interrupted before the path was traced; nothing to resume (run again "
                          "to start over)", file=sys.stderr, flush=True)
            return EXIT_INTERRUPTED
        with _sigint_ignored():
            progress.done()
            if run.abandon() and not isinstance(exc, InputError):  # bad input: its one message says it all
                print(f"cfcontact: a checkpoint remains in {run.partial} (cfcontact run --resume)", file=sys.stderr)
        raise
    finally:
        _ProgressAwareHandler.progress = None
    progress.done()
    s = path.summary()
    if runner.interrupted:  # the Ctrl-C came after the last output: the run's folder is complete
        print(f"cfcontact run: interrupted (the outputs were complete: {run.out}/)", file=sys.stderr, flush=True)
        return EXIT_INTERRUPTED
    _say(args, f"cfcontact: {s['status']}: {s['points']} points, {s['branches']} branches, {s['transitions']} "
               f"transitions ({s['folds']} folds), max multiplicity {s['max_multiplicity']}; wrote {run.out}/ "
               f"({', '.join(files)})")
    return EXIT_INCOMPLETE if s["status"] in INCOMPLETE_STATUSES else EXIT_OK


def _load_saved(dirname):
    src = resolve_saved(dirname)
    path = load_saved_path(src)
    _default_sigpipe()
    return src, path


def cmd_schema(args):
    """``cfcontact schema``: the case-file reference (annotated TOML, from cfcontact.case.SCHEMA)."""
    sys.stdout.write(reference_text())
    return EXIT_OK


def cmd_plot(args):
    if args.multiplicity and (args.component is not None or args.zoom):  # (plots of alpha against a component)
        raise CaseError(f"{'--component' if args.component is not None else '--zoom'}: not with --multiplicity (the "
                        "number of solutions over alpha has no component and no zoom panel); give one or the other")
    src, path = _load_saved(args.saved)
    component = parse_component(args.component, "--component") if args.component is not None else None
    if component is not None:
        path.component_index(component)
    zoom = list(args.zoom) if args.zoom else None
    if zoom and not zoom[0] < zoom[1]:
        raise CaseError(f"--zoom: need A < B, got {zoom[0]} {zoom[1]}")
    if zoom and len(path.alphas) and (zoom[1] < path.alphas.min() or zoom[0] > path.alphas.max()):
        # (the library's message asks for value limits, which --zoom cannot take)
        raise CaseError(f"--zoom {zoom[0]:g} {zoom[1]:g}: the path has no points there; it covers "
                        f"{path.parameter_name} in [{path.alphas.min():.10g}, {path.alphas.max():.10g}]")
    out = args.output or ("multiplicity.png" if args.multiplicity else "path.png")
    if os.path.splitext(out)[1].lower() not in (".png", ".pdf"):
        raise CaseError(f"-o: unsupported figure format {out!r}; use .png or .pdf")
    output_file(out)
    from cfcontact.plotting import plot_multiplicity, plot_path, save_figure

    if args.multiplicity:
        fig = plot_multiplicity(path, xlabel=parameter_label(path))
    else:
        try:
            fig = plot_path(path, component=component, zoom=zoom, xlabel=parameter_label(path))
        except InputError as exc:
            if zoom is None:
                raise
            raise InputError(f"--zoom: {exc}") from None
    save_figure(fig, out)
    _say(args, f"wrote {out}")
    return EXIT_OK


def _animation_target(args):
    """Check (and prepare the folder of) ``--animation``: a .gif/.mp4 file or a folder of frames."""
    ext = os.path.splitext(args.animation)[1].lower()
    if ext and ext not in (".gif", ".mp4"):
        raise CaseError(f"--animation: {ext!r} is not a format cfcontact writes; give a .gif or .mp4 file, or a "
                        "folder name without extension (PNG frames)")
    if args.frames > MAX_FRAMES:
        raise CaseError(f"--frames: at most {MAX_FRAMES}, got {args.frames}")
    if ext:
        output_file(args.animation, "--animation")
    else:
        output_folder(os.path.dirname(os.path.abspath(args.animation)), repr(args.animation), "--animation")


def _render_animation(args, path, ws, src):
    from cfcontact import render

    stress = None
    if args.stress:  # cells coloured by the von Mises stress, one scale for all frames
        from cfcontact import fields

        material = saved_material(src, path)

        def stress(sol):
            return fields.von_mises(path.geometry, sol, material)  # (at its alpha: prescribed u)

    res = render.render_animation(path, args.animation, frames=args.frames, magnification=args.magnification,
                                  window_size=ws or (960, 640), stress=stress)
    if res.note:
        _warn(args, res.note)
    _say(args, f"wrote {res.path} ({res.kind}, {res.frames} frames)")


def cmd_render(args):
    src, path = _load_saved(args.saved)
    if path.geometry is None:
        raise CaseError(f"{src!r} has no geometry (a lumped model): nothing to render")
    if args.magnification is None:
        args.magnification = _saved_magnification(src)
    from cfcontact import render

    ws = tuple(args.window_size) if args.window_size else None
    if ws is not None and min(ws) < 16:
        raise CaseError(f"--window-size: width and height must be >= 16, got {ws}")
    if args.animation:
        _animation_target(args)
    if args.animation and args.alpha is None and not args.panel and args.output is None:
        _render_animation(args, path, ws, src)
        return EXIT_OK
    alpha = default_alpha(path) if args.alpha is None else args.alpha
    sols = path.solutions_at(alpha)
    if not sols:
        lo, hi = float(path.alphas.min()), float(path.alphas.max())
        raise CaseError(f"--alpha {alpha}: the path has no solution there; it covers {path.parameter_name} in [{lo:.10g}, "
                        f"{hi:.10g}]")
    out = args.output or "render.png"
    if os.path.splitext(out)[1].lower() != ".png":
        raise CaseError(f"-o: renders are PNG files, got {out!r}")
    output_file(out)
    stresses = None
    if args.stress:
        from cfcontact import fields

        material = saved_material(src, path)
        stresses = [fields.von_mises(path.geometry, s, material) for s in sols]
    if len(sols) > 1 or args.panel:
        render.render_panel(path.geometry, sols, out, magnification=args.magnification, window_size=ws,
                            stresses=stresses, parameter=path.parameter_name)
    else:
        render.render_solution(path.geometry, sols[0], out, magnification=args.magnification,
                               window_size=ws or (1200, 800), stress=None if stresses is None else stresses[0],
                               parameter=path.parameter_name)
    _say(args, f"wrote {out} ({len(sols)} solution(s) at {path.parameter_name} = {alpha:.10g})")
    if args.animation:
        _render_animation(args, path, ws, src)
    return EXIT_OK


def cmd_export(args):
    src, path = _load_saved(args.saved)
    if path.geometry is None:
        raise CaseError(f"{src!r} has no geometry (a lumped model): nothing to export")
    out = args.output or "solutions.xdmf"
    if os.path.splitext(out)[1].lower() not in (".xdmf", ".xmf"):
        raise CaseError(f"-o: XDMF files end in .xdmf or .xmf, got {out!r}")
    output_file(out)
    from cfcontact import fields

    try:
        material = saved_material(src, path)
    except CaseError:
        material = None
        _warn(args, f"{src!r} stores no material: no von_mises attribute")
    alpha = default_alpha(path) if args.alpha is None and not args.points else args.alpha  # (as render)
    fn, what = fields.export_path(path, out, alpha=alpha, points=args.points, material=material)
    _say(args, f"wrote {fn} ({what})")
    return EXIT_OK


def _saved_magnification(src):
    """[output] magnification of the case a saved run was run from (its case.toml beside path/),
    or None (not given, a path saved by the library, or unreadable): ``render``'s default, as
    the run's own pictures had it."""
    toml = os.path.join(os.path.dirname(os.path.abspath(src)), "case.toml")
    try:
        import tomllib

        with open(toml, "rb") as fh:
            value = tomllib.load(fh).get("output", {}).get("magnification")
    except (OSError, ValueError, AttributeError):
        return None
    return float(value) if isinstance(value, (int, float)) and not isinstance(value, bool) and value > 0 else None


def _saved_contact_settings(src):
    """The pairing asked for by the case a saved path was run from (:func:`cfcontact.case.contact_settings`
    of the [geometry] and [contact] sections of the run folder's case.toml, <out>/path, or of a stopped
    run's checkpoint, <out>.partial/checkpoint/path); None when there is neither (a path saved by the
    library) or it cannot be read."""
    from cfcontact.case import contact_settings

    folder = os.path.dirname(os.path.abspath(src))
    state, toml = os.path.join(folder, "state.json"), os.path.join(folder, "case.toml")
    try:
        if os.path.isfile(state):
            with open(state) as fh:
                sections = json.load(fh)["physics"]
        elif os.path.isfile(toml):
            import tomllib

            with open(toml, "rb") as fh:
                sections = tomllib.load(fh)
        else:
            return None
        return contact_settings(sections.get("geometry") or {}, sections.get("contact") or {})
    except (OSError, ValueError, KeyError, TypeError, AttributeError):
        return None


def cmd_info(args):
    if args.saved.endswith(".toml") and os.path.isfile(args.saved):  # a case: build its model, report the pairing
        from cfcontact.case import build_system
        from cfcontact.errors import PairingWarning
        from cfcontact.report import format_model_report, model_report

        case = load_case(args.saved)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", PairingWarning)  # (the report lists the excluded nodes)
            system = build_system(case)
        rep = model_report(system, case["_file"], kind=case["geometry"]["kind"])
        print(json.dumps(rep, indent=1) if args.json else format_model_report(rep))
        return EXIT_OK
    src, path = _load_saved(args.saved)
    rep = path_report(path, _saved_contact_settings(src))
    timings = run_timings(src)
    if timings is not None:
        rep["timings"] = timings
    if args.json:
        print(json.dumps(rep, indent=1))
    else:
        print(format_report(rep, src))
    return EXIT_OK


# ============================================================ argument parsing
def _number(text, what="a finite number", ok=lambda v: True, kind=float):
    """An argparse type: ``kind(text)`` that is finite and passes ``ok``, else a message saying ``what``."""
    try:
        value = kind(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected {what}, got {text!r}") from None
    if not (math.isfinite(value) and ok(value)):
        raise argparse.ArgumentTypeError(f"expected {what}, got {text!r}")
    return value


def _finite(text):
    return _number(text)


def _alpha(text):
    return _number(text, f"a finite alpha with |alpha| <= {ALPHA_LIMIT:g}", lambda v: abs(v) <= ALPHA_LIMIT)


def _positive(text):
    return _number(text, "a finite number > 0", lambda v: v > 0)


def _non_negative(text):
    return _number(text, "a finite number >= 0", lambda v: v >= 0)


def _count(text):
    return _number(text, "an integer >= 1", lambda v: v >= 1, int)


def _pixels(text):
    return _number(text, "an integer from 16 to 10000", lambda v: 16 <= v <= 10000, int)


def _common():
    p = _Parser(add_help=False)
    g = p.add_mutually_exclusive_group()
    g.add_argument("-q", "--quiet", action="store_true", help="print nothing but errors")
    g.add_argument("-v", "--verbose", action="store_true",
                   help="log the library's progress (INFO), progress line even without a TTY, tracebacks")
    return p


def _setup_run(sub, common):
    p = sub.add_parser("run", parents=[common], help="trace the solution path of a case file",
                       description="Validate CASE.toml, build the model, trace the path and write the results.")
    p.add_argument("case", metavar="CASE.toml")
    p.add_argument("-o", "--output", metavar="DIR", help="output folder (default: <case stem>_out/ next to the case)")
    p.add_argument("--force", action="store_true",
                   help="replace an existing output folder / discard a stopped run's checkpoint")
    p.add_argument("--resume", action="store_true", help="continue the stopped run in <output>.partial/")
    p.add_argument("--stop-after-folds", type=_count, metavar="N", help="stop (resumably) once the path has N folds")
    p.add_argument("--stop-after-transitions", type=_count, metavar="N",
                   help="stop (resumably) once the path has N transitions")
    p.add_argument("--stop-at-alpha", type=_alpha, metavar="A", help="stop (resumably) when the path reaches alpha A")
    p.add_argument("--time-limit", type=_positive, metavar="SECONDS",
                   help="stop (resumably) after this wall time (checked at each accepted point)")
    p.add_argument("--checkpoint-every", type=_non_negative, metavar="SECONDS", default=DEFAULT_CHECKPOINT_EVERY,
                   help=f"checkpoint interval while tracing (default {DEFAULT_CHECKPOINT_EVERY:g}; 0: only on stop)")
    p.add_argument("--allow-large", action="store_true",
                   help="run even when the estimated memory exceeds the memory available")
    p.set_defaults(func=cmd_run)


def _setup_plot(sub, common):
    p = sub.add_parser("plot", parents=[common], help="plot a saved path (alpha against a component)")
    p.add_argument("saved", metavar="SAVED_PATH_DIR")
    p.add_argument("--component", metavar="NAME:I", help="lam_n:12, lam_t:3, u:7 or an index of y "
                                                         "(default: the contact node whose lam_n varies most)")
    p.add_argument("--zoom", nargs=2, type=_finite, metavar=("A", "B"), help="add a zoom panel on alpha in [A, B]")
    p.add_argument("--multiplicity", action="store_true", help="plot the number of solutions over alpha instead")
    p.add_argument("-o", "--output", metavar="FILE", help="FILE.png or FILE.pdf (default path.png / multiplicity.png)")
    p.set_defaults(func=cmd_plot)


def _setup_render(sub, common):
    p = sub.add_parser("render", parents=[common], help="render deformed configurations of a saved path")
    p.add_argument("saved", metavar="SAVED_PATH_DIR")
    p.add_argument("--alpha", type=_finite, metavar="A",
                   help="render the solutions at alpha A (default: the alpha of largest multiplicity; the "
                        "path's last point where it has one solution everywhere)")
    p.add_argument("--panel", action="store_true", help="panel layout even for a single solution")
    p.add_argument("--animation", metavar="FILE", help="animation along the path: FILE.gif, FILE.mp4 or a folder")
    p.add_argument("--frames", type=_count, default=60, help="animation frames (default 60)")
    p.add_argument("--magnification", type=_positive,
                   help="displacement scale (default: the run's [output] magnification, else automatic)")
    p.add_argument("--window-size", nargs=2, type=_pixels, metavar=("W", "H"), help="picture size in pixels")
    p.add_argument("--stress", action="store_true", help="colour the cells by the von Mises stress")
    p.add_argument("-o", "--output", metavar="FILE.png", help="picture file (default render.png)")
    p.set_defaults(func=cmd_render)


def _setup_export(sub, common):
    p = sub.add_parser("export", parents=[common], help="write solutions of a saved path as XDMF (ParaView)",
                       description="Write the solutions at one alpha (default, as render: the alpha of largest "
                                   "multiplicity; the path's last point where it has one solution everywhere) "
                                   "or every stored path point as an XDMF 3 file with inline XML data: "
                                   "displacement, contact_state, lam_n, lam_t, body, von_mises.")
    p.add_argument("saved", metavar="SAVED_PATH_DIR")
    g = p.add_mutually_exclusive_group()
    g.add_argument("--alpha", type=_finite, metavar="A",
                   help="all solutions at alpha A (default, as render: the alpha of largest multiplicity; the "
                        "path's last point where it has one solution everywhere)")
    g.add_argument("--points", action="store_true", help="every stored path point, in path order (time series)")
    p.add_argument("-o", "--output", metavar="FILE.xdmf", help="XDMF file (default solutions.xdmf)")
    p.set_defaults(func=cmd_export)


def _setup_info(sub, common):
    p = sub.add_parser("info", parents=[common], help="transitions, folds, multiplicity, events, stats and contact "
                                                      "pairing of a path; the model and pairing of a case",
                       description="A saved path: status, transitions, folds, multiplicity, events, statistics, "
                                   "a run folder's timings (summary.json) and its contact pairing. A case file "
                                   "(CASE.toml): builds its model and reports its size and pairing (pairs, excluded "
                                   "nodes, initial gap).")
    p.add_argument("saved", metavar="SAVED_PATH_DIR|CASE.toml")
    p.add_argument("--json", action="store_true", help="print the report as JSON")
    p.set_defaults(func=cmd_info)


def cmd_bench(args):
    """``cfcontact bench``: the benchmark of :mod:`cfcontact.bench` (tables on stdout, JSON file)."""
    from cfcontact import bench

    if os.path.exists(args.output) and not os.path.isdir(args.output):
        raise CaseError(f"--output: {args.output!r} is a file, not a folder")
    output_folder(args.output, repr(args.output), "--output")
    return bench.run(args, " ".join(["cfcontact"] + sys.argv[1:]) if _PROGRAM["main"] else "cfcontact bench")


def _setup_bench(sub, common):
    p = sub.add_parser("bench", parents=[common], help="benchmark: A seed vs exact, B refined meshes, C long "
                                                       "interfaces, D hard cases, E friction map",
                       description="Parts A-E (see --part; default A and B at full size, Part B up to n = 1e6 "
                                   "DOFs: try --quick first); prints each part's table and writes "
                                   "<output>/bench.json. See docs/bench.md.")
    from cfcontact.bench import add_arguments

    add_arguments(p)
    p.set_defaults(func=cmd_bench)


def cmd_map(args):
    """``cfcontact map CASE.toml``: the friction map of the case's load path (:mod:`cfcontact.map_run`)."""
    from cfcontact.map_run import check_grid, map_case

    bad = [m for m in (args.mark or []) if not (math.isfinite(m) and m >= 0)]
    if bad:
        raise CaseError(f"--mark: friction coefficients are finite numbers >= 0, got {bad[0]}")
    if args.friction_range and not all(math.isfinite(F) and 0 <= F <= MAX_FRICTION for F in args.friction_range):
        raise CaseError(f"--friction-range: need 0 <= F0 < F1 <= {MAX_FRICTION:g}, got {args.friction_range[0]} "
                        f"{args.friction_range[1]}")
    check_grid(args.friction_range, args.frictions, args.alphas)  # (before any folder is made)
    case = load_case(args.case)
    if args.output:
        output_folder(os.path.dirname(os.path.abspath(args.output)), repr(args.output), "-o")
    _say(args, f"cfcontact: friction map of {os.path.basename(case['_file'])}")
    res = map_case(case, args.output, tuple(args.friction_range) if args.friction_range else None,
                   args.frictions, args.alphas, args.mark, curves=not args.no_curves, force=args.force)
    _default_sigpipe()
    crit = res["critical"]
    if res["untraced"]:
        shown = ", ".join(f"F = {F:.10g} ({st})" for F, st in res["untraced"][:5])
        _warn(args, f"{len(res['untraced'])} row(s) of the map could not be traced to the end of the alpha range and "
                    f"are marked -1 (unknown): {shown}" + (", ..." if len(res["untraced"]) > 5 else ""))
    _say(args, f"cfcontact: critical friction of the path: {crit if crit is not None else '(no curves computed)'}")
    _say(args, f"cfcontact: up to {res['max_solutions']} solutions, {res['curves']} fold curve(s), {res['cusps']} "
               f"cusp(s); wrote {res['output']}/ ({', '.join(res['files'])})")
    return EXIT_INCOMPLETE if res["untraced"] else EXIT_OK


def _setup_map(sub, common):
    from cfcontact.map_run import DEFAULT_POINTS

    p = sub.add_parser("map", parents=[common], help="friction map of a case's load path: solution counts over "
                                                     "(alpha, F), fold curves, critical F",
                       description="Trace the exact alpha-path of CASE.toml for every friction coefficient of a "
                                   "grid and count its solutions (map.png), follow its folds exactly in F (fold "
                                   "curves, cusps, the smallest F with a fold) and write map.json and map.npz.")
    p.add_argument("case", metavar="CASE.toml")
    p.add_argument("-o", "--output", metavar="DIR", help="output folder (default: <case stem>_map/ next to the case)")
    p.add_argument("--force", action="store_true", help="replace an existing output folder")
    p.add_argument("--friction-range", nargs=2, type=float, metavar=("F0", "F1"),
                   help="friction range (default: 0 to the case's friction, at least 1)")
    p.add_argument("--frictions", type=int, default=DEFAULT_POINTS, metavar="N",
                   help=f"grid points in F (default {DEFAULT_POINTS})")
    p.add_argument("--alphas", type=int, default=DEFAULT_POINTS, metavar="N",
                   help=f"grid points in alpha (default {DEFAULT_POINTS})")
    p.add_argument("--mark", type=float, action="append", metavar="F",
                   help="draw a line at this friction (repeatable; default: the case's friction)")
    p.add_argument("--no-curves", action="store_true", help="the map only (no fold curves, no critical F)")
    p.set_defaults(func=cmd_map)


def _setup_schema(sub, common):
    p = sub.add_parser("schema", parents=[common], help="print the case-file reference (annotated TOML)",
                       description="Print every section and key of a case file with its type, default and "
                                   "meaning, as a TOML file (itself a valid case).")
    p.set_defaults(func=cmd_schema)


#: (name, setup(subparsers, common_parent)) of every subcommand.  A subcommand's
#: ``cmd_*(args)`` returns an exit code and raises CaseError / InputError for bad input (exit 2).
SUBCOMMANDS = [("run", _setup_run), ("plot", _setup_plot), ("render", _setup_render), ("info", _setup_info),
               ("export", _setup_export), ("bench", _setup_bench), ("schema", _setup_schema), ("map", _setup_map)]


class _Parser(argparse.ArgumentParser):
    """argparse with a one-line usage error: ``cfcontact run: error: ... (see cfcontact run --help)``."""

    def error(self, message):
        self.exit(EXIT_INPUT, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


def build_parser():
    from cfcontact import __version__

    parser = _Parser(prog="cfcontact", description="Path following for 2D static contact with "
                                     "Coulomb friction (FEniCSx + PETSc).")
    parser.add_argument("--version", action="version", version=f"cfcontact {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True
    common = _common()
    for _, setup in SUBCOMMANDS:
        setup(sub, common)
    return parser


def main(argv=None) -> int:
    """Entry point of the ``cfcontact`` command; returns the exit code.

    A Ctrl-C anywhere prints one line and gives 130 (never a traceback): inside a command as
    the command decides (``run`` keeps its checkpoint), elsewhere here; as the program, a Ctrl-C
    after the command (while Python, MPI and PETSc shut down) exits with 130 at once."""
    _PROGRAM["main"] = argv is None
    lost = []
    if _PROGRAM["main"]:
        sys.unraisablehook = _lost_interrupt_hook(lost)
    try:
        code = _main(argv)
    except KeyboardInterrupt:
        print("cfcontact: interrupted", file=sys.stderr, flush=True)
        code = EXIT_INTERRUPTED
    if lost and code == EXIT_OK:  # the Ctrl-C hit a finalizer (garbage collection) and the work went on
        print("cfcontact: interrupted (the command had finished its work)", file=sys.stderr, flush=True)
        code = EXIT_INTERRUPTED
    if _PROGRAM["main"]:
        _exit_on_late_interrupt()
    return code


def _lost_interrupt_hook(lost):
    """sys.unraisablehook: a KeyboardInterrupt raised inside a finalizer or weakref callback
    (Python ignores it there and prints "Exception ignored ... Traceback") is noted in ``lost``
    without a word; anything else goes to Python's hook."""
    def hook(unraisable):
        if unraisable.exc_type is not None and issubclass(unraisable.exc_type, KeyboardInterrupt):
            lost.append(unraisable)
            return
        sys.__unraisablehook__(unraisable)

    return hook


def _exit_on_late_interrupt():
    """After the command: a Ctrl-C while the interpreter shuts down (atexit handlers of MPI and
    PETSc) exits with 130 and one line, instead of a traceback under the command's exit code."""
    if threading.current_thread() is not threading.main_thread():
        return

    def handler(signum, frame):
        for stream in (sys.stdout, sys.stderr):
            try:
                stream.flush()
            except (OSError, ValueError):  # a closed pipe: nothing more to say there
                pass
        os.write(2, b"cfcontact: interrupted\n")
        os._exit(EXIT_INTERRUPTED)

    signal.signal(signal.SIGINT, handler)


#: (size, rank) variables of the MPI launchers: Open MPI, MPICH / Intel MPI (Hydra), PMIx
_MPI_ENV = (("OMPI_COMM_WORLD_SIZE", "OMPI_COMM_WORLD_RANK"), ("PMI_SIZE", "PMI_RANK"), ("PMIX_SIZE", "PMIX_RANK"))


def mpi_launch() -> tuple:
    """(ranks, rank) of the MPI job this process was started in: from the launcher's environment,
    or from mpi4py's COMM_WORLD when mpi4py is already imported (it is not imported for this);
    (1, 0) when not started by mpirun."""
    for size_var, rank_var in _MPI_ENV:
        try:
            size = int(os.environ.get(size_var, "1"))
            rank = int(os.environ.get(rank_var, "0"))
        except ValueError:
            continue
        if size > 1:
            return size, rank
    mpi = sys.modules.get("mpi4py.MPI")
    if mpi is not None and mpi.Is_initialized():
        return mpi.COMM_WORLD.size, mpi.COMM_WORLD.rank
    return 1, 0


def _main(argv) -> int:
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:  # argparse: --help / --version (0) or a usage error (2)
        return int(exc.code or 0)
    ranks, rank = mpi_launch()
    if ranks > 1:
        # every rank would run the whole command and write the same files: refused before any work
        # (the library's solvers run under MPI; the command line writes files from one process)
        if rank == 0:
            print(f"cfcontact {args.command}: error: the command line runs as one process, but it was started as "
                  f"{ranks} MPI ranks (mpirun -n {ranks}); run it without mpirun, or run a Python script under "
                  f"mpirun: every solver of the library runs in parallel (docs/cli.md, \"Parallel runs\")",
                  file=sys.stderr, flush=True)
        return EXIT_INPUT
    level = logging.ERROR if args.quiet else logging.INFO if args.verbose else logging.WARNING
    with _logging(level), _python_warnings(args):
        try:
            _no_empty_names(args)
            return int(args.func(args) or 0)
        except (CaseError, InputError) as exc:
            print(f"cfcontact {args.command}: error: {exc}", file=sys.stderr, flush=True)
            return EXIT_INPUT
        except (KeyboardInterrupt, Exception) as exc:
            if caused_by_interrupt(exc):  # a Ctrl-C, or one that a library re-raised as another error
                print(f"cfcontact {args.command}: interrupted", file=sys.stderr, flush=True)
                return EXIT_INTERRUPTED
            if args.verbose:
                traceback.print_exc()
            kind = "" if isinstance(exc, CfcontactError) else f"{type(exc).__name__}: "
            print(f"cfcontact {args.command}: failed: {kind}{exc}"
                  + ("" if args.verbose else "  (--verbose for the traceback)"), file=sys.stderr, flush=True)
            return EXIT_FAILURE


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
