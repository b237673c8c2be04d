"""Running a case file: the runner, checkpoints and the output folder.

A run (:class:`CaseRun`) works in ``<out>.partial/`` and renames it to ``<out>/`` only when
everything is written, so ``<out>/`` is always complete.  While the path is traced, the
:class:`Runner` (the stepper's callback, :mod:`cfcontact.stepper`) shows progress, checks the
stop conditions (:class:`StopConditions`) and asks for a checkpoint ``<out>.partial/checkpoint/``
(``path/`` = the live path, ``state.json`` = the method's resume state and the physics sections
of the case) every ``checkpoint_every`` seconds: a save, the run goes on.  A stop condition (or
an interrupt) stops the run at an accepted point, saves the checkpoint and raises
:class:`Stopped`; ``CaseRun(..., resume=True)`` continues from the checkpoint and the result
equals an uninterrupted run.  When tracing ends the traced path is checkpointed at once
(``state.json`` with ``"traced": true``), so an interrupt while the outputs are written (plots,
renders: most of a run's wall time) leaves a checkpoint whose resume only writes the outputs.

One run at a time per output folder: :class:`OutputLock` holds an advisory lock
(``fcntl.flock``) on ``<out>.lock`` next to it, with the holder's PID and start time, for the
whole run; a second run into the same folder (``--force`` included) is refused with the PID
(the kernel drops the lock of a dead process, so a killed run's lock is taken over).  At
the start of a run the leftovers of killed runs are removed: a ``<out>.partial/`` without a
checkpoint, the temporary folders of an interrupted save (``.checkpoint-new``, ``.cfpath-*``),
partial outputs beside a checkpoint, ``<out>.old`` (put back as ``<out>`` when a replacement
was stopped between its two renames).

Library code: nothing here prints; progress goes to a display object (``update(text, force)``,
``clear()``, ``done()``) and warnings to a callable, both given by the caller (the command line).
"""

from __future__ import annotations

import errno
import fcntl
import json
import logging
import math
import os
import shutil
import socket
import tempfile
import time
import tomllib
from dataclasses import dataclass
from typing import Callable, Optional

from cfcontact.case import CaseError, build_system, path_request, physics
from cfcontact.errors import InputError, StartInterrupted
from cfcontact.jsonio import blocking_file, holds_format, read_json, write_json
from cfcontact.material import DEFAULT_MATERIAL
from cfcontact.path import path_stepper, select_solver
from cfcontact.report import path_report
from cfcontact.solution_path import SolutionPath, component_index
from cfcontact.stepper import CHECKPOINT

log = logging.getLogger(__name__)

__all__ = ["CaseRun", "Runner", "StopConditions", "Stopped", "OutputLock", "save_checkpoint", "load_checkpoint",
           "has_checkpoint", "write_outputs", "panel_solutions", "default_alpha", "resolve_saved", "saved_material", "load_saved_path",
           "parameter_label", "output_folder", "replaceable_output", "run_timings", "RUN_FORMAT",
           "CHECKPOINT_FORMAT", "DEFAULT_CHECKPOINT_EVERY"]

RUN_FORMAT, CHECKPOINT_FORMAT = "cfcontact-run", "cfcontact-checkpoint"
DEFAULT_CHECKPOINT_EVERY = 60.0
#: Folders of a checkpoint inside ``<out>.partial/`` (the second one during a swap).
CHECKPOINT_DIRS = ("checkpoint", ".checkpoint-old")


class Stopped(Exception):
    """The run was stopped before its end; a checkpoint was written (``resumable``: with a resume
    state), unless ``checkpoint`` is False (stopped while its start was being reached: the path had
    no point yet)."""

    def __init__(self, reason, interrupted=False, resumable=True, checkpoint=True):
        super().__init__(reason)
        self.reason, self.interrupted, self.resumable = reason, interrupted, resumable
        self.checkpoint = checkpoint


@dataclass(frozen=True)
class StopConditions:
    """When a run stops early (resumably) and how often it saves a checkpoint.

    time_limit: seconds since the runner started; stop_after_folds / stop_after_transitions:
    totals along the whole path (a condition already met when resuming is not triggered again);
    stop_at_alpha: the first accepted point at or beyond it; checkpoint_every: seconds between
    checkpoints (0: only when stopping)."""

    time_limit: Optional[float] = None
    stop_after_folds: Optional[int] = None
    stop_after_transitions: Optional[int] = None
    stop_at_alpha: Optional[float] = None
    checkpoint_every: float = DEFAULT_CHECKPOINT_EVERY

    def __post_init__(self):
        for name in ("stop_after_folds", "stop_after_transitions"):
            v = getattr(self, name)
            if v is not None and v < 1:
                raise CaseError(f"{name} must be >= 1, got {v}")
        if self.time_limit is not None and not self.time_limit > 0:
            raise CaseError(f"time_limit must be > 0 seconds, got {self.time_limit}")
        if not self.checkpoint_every >= 0:
            raise CaseError(f"checkpoint_every must be >= 0 seconds, got {self.checkpoint_every}")


class _NoDisplay:
    def update(self, text, force=False):
        pass

    def clear(self):
        pass

    def done(self):
        pass


class Runner:
    """The callback of a traced case: progress line, stop conditions, checkpoint timing.

    :meth:`on_point` answers None (go on), :data:`~cfcontact.stepper.CHECKPOINT` (save and go on)
    or the reason to stop (a string).  :meth:`interrupt` (e.g. from a SIGINT handler) stops the
    run at the next accepted point."""

    def __init__(self, stops: StopConditions, display=None, t_start: Optional[float] = None):
        self.stops = stops
        self.display = display if display is not None else _NoDisplay()
        self.t_start = time.monotonic() if t_start is None else t_start
        self.interrupted = False
        self.reason = None
        self.solver = None

    def interrupt(self):
        self.interrupted = True

    def begin(self, solver, resumed_path: Optional[SolutionPath] = None):
        """Start counting: the solver's work from now on, the counts of a resumed path."""
        self.solver = solver
        self.solves0 = solver.stats.linear_solves
        self.solves_before = int(resumed_path.stats.get("linear_solves", 0)) if resumed_path is not None else 0
        # counts already reached when (re)starting: a condition already met is not triggered again
        self.folds0 = len(resumed_path.folds) if resumed_path is not None else 0
        self.trans0 = len(resumed_path.transitions) if resumed_path is not None else 0
        self.prev_alpha = float(resumed_path.alphas[-1]) if resumed_path is not None else None
        self.last_checkpoint = time.monotonic()
        self.points = 0

    def status_line(self, alpha, branches, transitions, folds):
        solves = self.solves_before + self.solver.stats.linear_solves - self.solves0
        return (f"alpha={alpha:.8g}  branches {branches}  transitions {transitions}  folds {folds}  "
                f"linear solves {solves}  "
                f"{time.monotonic() - self.t_start:.1f} s")

    def on_point(self, pt):
        self.points += 1
        path = pt.path  # the live path
        folds, transitions, branches = len(path.folds), len(path.transitions), len(path.branches)
        self.display.update(self.status_line(pt.alpha, branches, transitions, folds))
        stops = self.stops
        prev, self.prev_alpha = self.prev_alpha, float(pt.alpha)
        if self.interrupted:
            self.reason = "interrupted (Ctrl-C)"
        elif stops.time_limit is not None and time.monotonic() - self.t_start >= stops.time_limit:
            self.reason = f"time limit of {stops.time_limit:g} s reached"
        elif stops.stop_after_folds is not None \
                and folds > self.folds0 and folds >= stops.stop_after_folds:
            self.reason = f"stopped after {folds} fold(s)"
        elif stops.stop_after_transitions is not None and transitions > self.trans0 \
                and transitions >= stops.stop_after_transitions:
            self.reason = f"stopped after {transitions} transition(s)"
        elif stops.stop_at_alpha is not None and prev is not None \
                and (pt.alpha - stops.stop_at_alpha) * (prev - stops.stop_at_alpha) <= 0 and pt.alpha != prev:
            self.reason = f"stopped at {path.parameter_name}={pt.alpha:.8g} (reached {stops.stop_at_alpha:g})"
        elif stops.checkpoint_every and time.monotonic() - self.last_checkpoint >= stops.checkpoint_every:
            return CHECKPOINT
        return self.reason

    def on_start(self, progress):
        """The monitor of a long start (a :class:`~cfcontact.StartProgress`, before the
        path's first point): the progress line, and the reason to abandon the run (Ctrl-C, the
        time limit) or None.  The conditions on the path (folds, transitions, alpha) wait for it."""
        self.display.update(f"reaching the start ({progress.stage}): t={progress.t:.6g}  transitions "
                            f"{progress.transitions}  {time.monotonic() - self.t_start:.1f} s")
        if self.interrupted:
            self.reason = "interrupted (Ctrl-C)"
        elif self.stops.time_limit is not None and time.monotonic() - self.t_start >= self.stops.time_limit:
            self.reason = f"time limit of {self.stops.time_limit:g} s reached"
        return self.reason

    def checkpoint_saved(self):
        self.last_checkpoint = time.monotonic()

    def end(self, path):
        """The final progress line."""
        self.display.update(self.status_line(path.alphas[-1], len(path.branches), len(path.transitions),
                                             len(path.folds)), force=True)
        self.display.done()


# ============================================================ the lock
def _flock_holder_pid(file) -> Optional[int]:
    """The PID holding an flock on ``file`` according to Linux' /proc/locks, or None (another
    system, no such lock, or the file gone)."""
    try:
        st = os.stat(file)
        with open("/proc/locks") as fh:
            lines = fh.read().splitlines()
    except OSError:
        return None
    ident = f"{os.major(st.st_dev):02x}:{os.minor(st.st_dev):02x}:{st.st_ino}"
    for line in lines:
        fields = line.split()
        if "FLOCK" in fields and "->" not in fields and ident in fields:
            try:
                return int(fields[fields.index(ident) - 1])
            except (ValueError, IndexError):
                return None
    return None


class OutputLock:
    """An advisory lock (``fcntl.flock``) on ``<out>.lock`` beside the output folder ``out``.

    :meth:`acquire` raises CaseError naming the holder (PID, start time, host, command) when
    another live process holds it, or when the lock file cannot be created (an unwritable or
    missing parent).  :meth:`release` removes the file while still holding the lock; an
    acquirer that locked a file removed meanwhile notices (another inode) and tries again."""

    def __init__(self, out):
        self.out = out
        self.file = out + ".lock"
        self.fd = None

    def holder(self) -> dict:
        """What the lock file says about its holder ({} if unreadable)."""
        try:
            with open(self.file) as fh:
                info = json.loads(fh.read() or "{}")
        except (OSError, ValueError):
            return {}
        return info if isinstance(info, dict) else {}

    def acquire(self, command: str = "cfcontact run"):
        while self.fd is None:
            try:
                fd = os.open(self.file, os.O_RDWR | os.O_CREAT, 0o644)
            except OSError as exc:
                raise CaseError(f"cannot write the output folder {self.out!r}: {exc.strerror} ({self.file!r})") \
                    from None
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except OSError as exc:
                os.close(fd)
                if exc.errno not in (errno.EWOULDBLOCK, errno.EAGAIN, errno.EACCES):
                    raise CaseError(f"cannot lock the output folder {self.out!r}: {exc.strerror}") from None
                info = self.holder()
                for _ in range(100):  # the holder writes its details right after locking: wait for them
                    if "pid" in info:
                        break
                    time.sleep(0.01)
                    info = self.holder()
                if "pid" not in info:  # a holder stopped before writing them: the kernel knows its PID
                    pid = _flock_holder_pid(self.file)
                    if pid is not None:
                        info = {"pid": pid}
                who = (f"process {info.get('pid', '?')} ({info.get('command', 'cfcontact run')}, started "
                       f"{time.strftime('%Y-%m-%d %H:%M:%S', time.localtime(info['time']))} on "
                       f"{info.get('host', '?')})" if isinstance(info.get("time"), (int, float)) else
                       f"process {info.get('pid', '?')}")
                raise CaseError(f"the output folder {self.out!r} is in use by another run: {who} holds "
                                f"{self.file!r}; wait for it to end or choose another --output") from None
            try:
                same = os.path.samestat(os.fstat(fd), os.stat(self.file))
            except FileNotFoundError:
                same = False
            if not same:  # released and removed between our open and our lock: lock the new file
                os.close(fd)
                continue
            os.ftruncate(fd, 0)
            os.write(fd, json.dumps({"pid": os.getpid(), "time": time.time(), "host": socket.gethostname(),
                                     "command": command}).encode())
            self.fd = fd
        return self

    def release(self):
        if self.fd is None:
            return
        try:
            os.unlink(self.file)
        except FileNotFoundError:
            pass
        finally:
            fcntl.flock(self.fd, fcntl.LOCK_UN)
            os.close(self.fd)
            self.fd = None


# ============================================================ checkpoints
def save_checkpoint(partial, path, case, reason, resume_state, replace=False):
    """Write ``<partial>/checkpoint/`` (path/ + state.json) atomically.  ``replace``: the run was
    started with ``--force``, so its resume replaces an existing output folder, as the run would
    have (state.json's ``"replace"``)."""
    return _write_checkpoint(partial, path, case, reason, resume_state, replace=replace)


def save_traced(partial, path, case, replace=False):
    """The checkpoint of a traced path (``"traced": true``): resuming it only writes the outputs."""
    return _write_checkpoint(partial, path, case, "traced", None, traced=True, replace=replace)


def _write_checkpoint(partial, path, case, reason, resume_state, traced=False, replace=False):
    final = os.path.join(partial, CHECKPOINT_DIRS[0])
    tmp = os.path.join(partial, ".checkpoint-new")
    shutil.rmtree(tmp, ignore_errors=True)
    os.makedirs(tmp)
    path.save(os.path.join(tmp, "path"))
    state = {"format": CHECKPOINT_FORMAT, "version": 1, "reason": reason, "time": time.time(),
             "method": path.method, "resumable": traced or resume_state is not None, "traced": bool(traced),
             "resume_state": resume_state, "physics": physics(case), "system_checksum": path.system_checksum,
             "case_file": case["_file"], "summary": path.summary(), "replace": bool(replace)}
    write_json(os.path.join(tmp, "state.json"), state)
    old = os.path.join(partial, CHECKPOINT_DIRS[1])
    shutil.rmtree(old, ignore_errors=True)
    if os.path.isdir(final):
        os.rename(final, old)
    os.rename(tmp, final)
    shutil.rmtree(old, ignore_errors=True)
    log.info("checkpoint written to %s (%s)", final, reason)
    return final


def load_checkpoint(partial):
    """(state dict, SolutionPath) of ``<partial>/checkpoint`` (or the old one of an interrupted swap)."""
    for name in CHECKPOINT_DIRS:
        ck = os.path.join(partial, name)
        if os.path.isfile(os.path.join(ck, "state.json")) and os.path.isdir(os.path.join(ck, "path")):
            state = _read_state(os.path.join(ck, "state.json"))
            try:
                saved = load_saved_path(os.path.join(ck, "path"))
            except InputError as exc:
                raise CaseError(f"the checkpoint is damaged: {exc}; start over with --force") from None
            if state["method"] != saved.method:
                raise CaseError(f"{ck}: state.json is of method {state['method']!r}, path/ of {saved.method!r}; "
                                f"start over with --force")
            if state.get("traced") and saved.status in ("running", "stopped by callback"):
                raise CaseError(f"{ck}: state.json says the path was traced to its end, but path/ is a stopped path "
                                f"(status {saved.status!r}); start over with --force")
            if state["system_checksum"] != saved.system_checksum:
                raise CaseError(f"{ck}: state.json and path/ belong to different systems (checksums "
                                f"{str(state['system_checksum'])[:12]}... and {str(saved.system_checksum)[:12]}...); "
                                f"start over with --force")
            return state, saved
    raise CaseError(f"nothing to resume: {partial!r} holds no checkpoint (the run was stopped before its first "
                    f"one); start over by running without --resume")


def _read_state(fn) -> dict:
    """state.json of a checkpoint, checked (CaseError naming the file and what is wrong)."""
    try:
        state = read_json(fn)
    except (OSError, UnicodeDecodeError, ValueError) as exc:
        raise CaseError(f"{fn}: unreadable or truncated ({exc}); start over with --force") from None
    if not isinstance(state, dict) or state.get("format") != CHECKPOINT_FORMAT:
        raise CaseError(f"{os.path.dirname(fn)}: not a cfcontact checkpoint")
    if state.get("version") != 1:
        raise CaseError(f"{fn}: checkpoint version {state.get('version')!r} is not one this cfcontact reads (1); "
                        "start over with --force")
    for key, kinds in (("resumable", bool), ("physics", dict), ("method", str)):
        if not isinstance(state.get(key), kinds):
            raise CaseError(f"{fn}: key {key!r} is missing or of the wrong type; start over with --force")
    rs = state.get("resume_state")
    if state["resumable"] and not state.get("traced") and not isinstance(rs, dict):
        raise CaseError(f"{fn}: key 'resume_state' is missing or not an object; start over with --force")
    bad = _non_finite(rs) if rs is not None else None
    if bad:
        raise CaseError(f"{fn}: resume_state {bad} is not a finite number; start over with --force")
    checksum = state.setdefault("system_checksum", None)
    if checksum is not None and not (isinstance(checksum, str) and len(checksum) == 64):
        raise CaseError(f"{fn}: system_checksum {checksum!r} is not a SHA-256 digest; start over with --force")
    return state


def _non_finite(value, where=""):
    """The location of the first non-finite number (or JSON null standing for one) in ``value``."""
    if isinstance(value, float) and not math.isfinite(value):
        return where or "(the value)"
    if isinstance(value, dict):
        for k, v in value.items():
            bad = _non_finite(v, f"{where}.{k}" if where else str(k))
            if bad:
                return bad
    if isinstance(value, list):
        for i, v in enumerate(value):
            bad = _non_finite(v, f"{where}[{i}]")
            if bad:
                return bad
    return None


def has_checkpoint(partial) -> bool:
    return any(os.path.isfile(os.path.join(partial, n, "state.json")) for n in CHECKPOINT_DIRS)


def damaged_checkpoint(partial) -> Optional[str]:
    """What is missing from a checkpoint folder of ``partial`` that holds some of a checkpoint's
    files but not all (``state.json`` or ``path/``), or None: no such folder (a complete checkpoint,
    or none at all: an empty ``checkpoint/`` is no checkpoint).  A save writes a checkpoint in
    ``.checkpoint-new/`` and renames it, so a partial one is damage, not a run stopped early."""
    if any(os.path.isfile(os.path.join(partial, n, "state.json")) and os.path.isdir(os.path.join(partial, n, "path"))
           for n in CHECKPOINT_DIRS):
        return None
    for name in CHECKPOINT_DIRS:
        ck = os.path.join(partial, name)
        try:
            held = os.listdir(ck) if os.path.isdir(ck) else []
        except OSError:
            held = []
        if held:
            missing = "state.json" if not os.path.isfile(os.path.join(ck, "state.json")) else "path/"
            return f"{os.path.join(ck, missing)} is missing"
    return None


# ============================================================ outputs
def _go_on(interrupted: Optional[Callable]):
    """KeyboardInterrupt when ``interrupted()`` says a Ctrl-C came (held back by the caller's
    handler while the outputs were written): the writing stops at this clean point."""
    if interrupted is not None and interrupted():
        raise KeyboardInterrupt


def write_outputs(path, case, outdir, timings, warn: Callable = log.warning, system=None, saved=None,
                  interrupted: Optional[Callable] = None):
    """Plots, renders, the saved path and summary.json into ``outdir``; returns the files written.
    ``saved``: a folder where ``path`` is already saved (the traced checkpoint): linked, not saved again.
    ``interrupted``: asked before each output (:meth:`CaseRun.finish`)."""
    out = case["output"]
    files = []
    t = time.perf_counter()
    if saved is not None and os.path.isdir(saved):
        _link_tree(saved, os.path.join(outdir, "path"))
    else:
        path.save(os.path.join(outdir, "path"))
    files.append("path/")
    with open(os.path.join(outdir, "case.toml"), "w") as fh:
        fh.write(case["_text"])
    files.append("case.toml")
    timings["save"] = time.perf_counter() - t
    _go_on(interrupted)
    component = out.get("component")
    if component is not None:
        path.component_index(component)  # range check (InputError)
    if out["plot"] and len(path.alphas):
        t = time.perf_counter()
        from cfcontact.plotting import plot_multiplicity, plot_path, save_figure

        try:
            fig = plot_path(path, component=component, zoom=out.get("zoom"),
                            title=case.get("title"), xlabel=parameter_label(path))
        except InputError as exc:  # a zoom window the path does not reach (it turned back before)
            if out.get("zoom") is None:
                raise
            warn(f"[output] zoom: {exc}; path.{out['plot_formats'][0]} has no zoom panel")
            fig = plot_path(path, component=component, title=case.get("title"), xlabel=parameter_label(path))
        for fmt in out["plot_formats"]:
            save_figure(fig, os.path.join(outdir, f"path.{fmt}"))
            files.append(f"path.{fmt}")
            _go_on(interrupted)
        if path.multiplicity_intervals():
            fig = plot_multiplicity(path, xlabel=parameter_label(path))
            for fmt in out["plot_formats"]:
                save_figure(fig, os.path.join(outdir, f"multiplicity.{fmt}"))
                files.append(f"multiplicity.{fmt}")
                _go_on(interrupted)
        timings["plot"] = time.perf_counter() - t
    if (out["render_panel"] or out["render_animation"] or out["xdmf"]) and path.geometry is None:
        warn("the path has no geometry; no renders" + (" and no XDMF file" if out["xdmf"] else ""))
    elif out["render_panel"] or out["render_animation"] or out["xdmf"]:
        t = time.perf_counter()
        files += _write_pictures(path, case, outdir, warn, interrupted)
        timings["render"] = time.perf_counter() - t
    summary = {"format": RUN_FORMAT, "version": 1, "case_file": case["_file"], "title": case.get("title"),
               "summary": path.summary(), **path_report(path), "timings": timings, "files": files}
    write_json(os.path.join(outdir, "summary.json"), summary)
    files.append("summary.json")
    return files


def _write_pictures(path, case, outdir, warn, interrupted=None) -> list:
    """solutions.xdmf, panel.png and the animation as the case's [output] asks; the files written."""
    out, files = case["output"], []
    ws = out.get("window_size")
    mag = out.get("magnification")
    sols = panel_solutions(path) if out["render_panel"] or out["xdmf"] else []
    if out["xdmf"] and sols:
        from cfcontact import fields

        fields.write_xdmf(os.path.join(outdir, "solutions.xdmf"), path.geometry, sols)
        files.append("solutions.xdmf")
        _go_on(interrupted)
    if out["render_panel"] and sols:
        from cfcontact import render

        stresses = None
        if out["stress"]:
            from cfcontact import fields

            stresses = [fields.von_mises(path.geometry, s) for s in sols]  # (at its alpha: prescribed u)
        log.info("writing %s", os.path.join(outdir, "panel.png"))
        render.render_panel(path.geometry, sols, os.path.join(outdir, "panel.png"), magnification=mag,
                            parameter=path.parameter_name,
                            window_size=None if ws is None else tuple(ws), stresses=stresses)
        files.append("panel.png")
        _go_on(interrupted)
    if out["render_animation"] and len(path.alphas):
        from cfcontact import render

        fmt = out["animation_format"]
        name = "animation_frames" if fmt == "frames" else f"animation.{fmt}"
        stress = None
        if out["stress"]:
            from cfcontact import fields

            def stress(sol):
                return fields.von_mises(path.geometry, sol)

        res = render.render_animation(path, os.path.join(outdir, name), frames=out["animation_frames"],
                                      magnification=mag, window_size=(960, 640) if ws is None else tuple(ws),
                                      title=case.get("title"), stress=stress)
        if res.note:
            warn(res.note)
        files.append(os.path.relpath(res.path, outdir) + ("/" if res.kind == "png-frames" else ""))
        _go_on(interrupted)
    return files


def default_alpha(path) -> float:
    """The alpha that ``render`` and ``export`` show without ``--alpha``, that of the run's
    panel and solutions.xdmf (:func:`panel_solutions`): the alpha of largest multiplicity where it
    is above one, else the path's last point (the farthest it reached).  CaseError when the path
    covers no interval."""
    k, a = path.max_multiplicity()
    if not k:
        raise CaseError(f"the path covers no {path.parameter_name} interval; give --alpha")
    return float(a) if k > 1 else float(path.alphas[-1])


def panel_solutions(path):
    """The solutions at the alpha of largest multiplicity, where it is above one (else the last
    path point: the farthest the path reached; :func:`default_alpha`)."""
    k, a = path.max_multiplicity()
    sols = path.solutions_at(a) if k > 1 else []
    if not sols and len(path.alphas):
        from cfcontact.ssnm import Solution

        y = path.point_y(len(path.alphas) - 1)
        n, m = path.n, path.m
        sols = [Solution(y[:n], y[n:n + m], y[n + m:], float(path.alphas[-1]),
                         path.branches[path.point_branch[-1]].sets, 0)]
    return sols


def output_folder(folder, what, flag=None) -> str:
    """``folder`` created if missing, to hold ``what`` (its description in messages); CaseError
    (prefixed by the command-line ``flag`` when given) where a file stands in its way, it cannot
    be created, or it takes no new files (a read-only or pseudo file system such as /proc, no
    write permission: checked by creating and removing a file in it, before any work)."""
    prefix = f"{flag}: " if flag else ""
    blocking = blocking_file(folder)
    if blocking is not None:
        raise CaseError(f"{prefix}cannot write {what}: {blocking!r} is a file, not a folder")
    try:
        os.makedirs(folder, exist_ok=True)
    except OSError as exc:
        raise CaseError(f"{prefix}cannot create the folder {folder!r} for {what}: {exc.strerror}") from None
    try:
        fd, probe = tempfile.mkstemp(dir=folder, prefix=".cfcontact-probe-")
        os.close(fd)
        os.remove(probe)
    except OSError as exc:
        raise CaseError(f"{prefix}cannot write {what}: the folder {folder!r} takes no new files "
                        f"({exc.strerror})") from None
    return folder


def replaceable_output(out, replace, ours, what):
    """CaseError unless the output folder ``out`` may be written: absent, or, with ``replace``
    (--force), a folder that ``ours(out)`` recognises as one cfcontact wrote (``what`` names
    that kind in the message).  A file standing there is named a file.  (run's and map's outputs.)"""
    if not os.path.exists(out):
        return
    if not os.path.isdir(out):
        raise CaseError(f"the output folder {out!r} is a file, not a folder; choose another --output")
    if not replace:
        raise CaseError(f"the output folder {out!r} exists; use --force to replace it or --output DIR")
    if not ours(out):
        raise CaseError(f"refusing to replace {out!r}: it is not {what}")


def _is_run_folder(d):
    return holds_format(d, "summary.json", RUN_FORMAT, empty=True)


def _link_tree(src, dst):
    """A copy of the folder ``src`` at ``dst`` by hard links (copies where links are refused)."""
    def link(a, b):
        try:
            os.link(a, b)
        except OSError:
            shutil.copy2(a, b)

    tmp = dst + ".tmp"
    shutil.rmtree(tmp, ignore_errors=True)
    shutil.copytree(src, tmp, copy_function=link)
    if os.path.isdir(dst):
        shutil.rmtree(dst)
    os.rename(tmp, dst)


def _remove(p):
    if os.path.isdir(p) and not os.path.islink(p):
        shutil.rmtree(p)
    else:
        os.remove(p)


# ============================================================ a run
class CaseRun:
    """One run of a validated case into its output folder (default ``<case stem>_out/`` next to
    the case file).  The constructor takes the folder's lock (:class:`OutputLock`) and checks the
    folders (CaseError: another run holds the folder, an existing output without ``force``, a
    stopped run's checkpoint without ``resume`` or ``force``, a checkpoint that does not match
    the case); :meth:`start`, :meth:`build`, :meth:`trace` and :meth:`finish` do the work,
    :meth:`abandon` cleans up after a failure and :meth:`close` releases the lock (also a
    context manager).  ``warn``: a callable for notes (leftovers of killed runs removed)."""

    def __init__(self, case, output=None, force=False, resume=False, warn: Callable = log.warning):
        self.case = case
        if output:
            out = os.path.abspath(output)
        else:
            stem = os.path.splitext(os.path.basename(case["_file"]))[0]
            out = os.path.join(os.path.dirname(case["_file"]), f"{stem}_out")
        self.out = out.rstrip(os.sep)
        self.partial = self.out + ".partial"
        self.resuming = bool(resume)
        self.timings = {}
        self.created = False
        self.resume = None
        self.replace = bool(force)  # an existing output folder is replaced at the end (--force)
        output_folder(os.path.dirname(self.out), f"the output folder {self.out!r}")
        self.lock = OutputLock(self.out).acquire()
        try:
            self._check_folders(force, resume, warn)
        except BaseException:
            self.lock.release()
            raise

    def close(self):
        """Release the output folder's lock."""
        self.lock.release()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    @property
    def traced(self) -> bool:
        """Does this run resume a complete (traced) path, so that only the outputs are left to write?"""
        return bool(self.resume and self.resume.get("traced"))

    def _check_folders(self, force, resume, warn):
        old = self.out + ".old"
        if os.path.isdir(old):  # a replacement (--force) killed halfway
            if os.path.isdir(self.out):  # after its new folder was in place
                shutil.rmtree(old, ignore_errors=True)
            else:  # between its two renames: the earlier results go back in place
                os.rename(old, self.out)
                warn(f"restored {self.out!r} from {old!r}, left by a replacement stopped halfway")
        damaged = damaged_checkpoint(self.partial)
        if damaged is not None and (resume or not force):  # kept: the user decides (--force starts over)
            raise CaseError(f"the checkpoint in {self.partial!r} is damaged: {damaged}; start over with --force")
        if os.path.exists(self.partial) and not has_checkpoint(self.partial) and damaged is None:
            # a run killed (or failed) before its first checkpoint: nothing in it can be resumed
            _remove(self.partial)
            if resume:
                raise CaseError(f"nothing to resume: the run that left {self.partial!r} was stopped before its first "
                                f"checkpoint (the folder is removed now); run without --resume to start over")
            warn(f"removed {self.partial!r}, left by a run stopped before its first checkpoint")
        if resume and not force and self._checkpoint_replaces():
            self.replace = True  # the stopped run was started with --force: its resume replaces <out>/ too
        replaceable_output(self.out, self.replace, _is_run_folder, "a cfcontact output folder")
        if resume:
            if not os.path.isdir(self.partial):
                raise CaseError(f"nothing to resume: no stopped run left {self.partial!r}; run without --resume")
            state, saved = load_checkpoint(self.partial)
            if not state.get("resumable"):
                raise CaseError(f"the checkpoint in {self.partial!r} (method {state.get('method')!r}) cannot be "
                                f"resumed; start over with --force")
            now = physics(self.case)
            changed = [k for k in now if state["physics"].get(k) != now[k]]
            if changed:
                raise CaseError(f"the case file changed since the checkpoint in section(s) "
                                f"{', '.join(f'[{k}]' for k in changed)}; restore it or start over with --force")
            self.resume = {"path": saved, "state": state["resume_state"], "traced": bool(state.get("traced"))}
        elif os.path.exists(self.partial):
            if not force:
                raise CaseError(f"a stopped run left a checkpoint in {self.partial!r}; continue it with --resume or "
                                f"start over with --force")
            shutil.rmtree(self.partial)

    def start(self):
        """Create ``<out>.partial/`` (when resuming: remove everything in it but the checkpoint,
        e.g. the temporary folders and partial outputs of a killed run)."""
        self.created = not os.path.isdir(self.partial)
        os.makedirs(self.partial, exist_ok=True)
        if self.resuming:
            for name in os.listdir(self.partial):
                if name not in CHECKPOINT_DIRS:
                    _remove(os.path.join(self.partial, name))

    def build(self):
        """The case's ContactSystem (timed; the [output] component is checked against it)."""
        t = time.perf_counter()
        system = build_system(self.case)
        self.timings["assembly"] = time.perf_counter() - t
        comp = self.case["output"].get("component")
        if comp is not None:
            try:
                component_index(system.n, system.m, comp)
            except InputError as exc:
                raise CaseError(f"[output] component: {exc}") from None
        return system

    def trace(self, system, runner: Runner) -> SolutionPath:
        """Trace the case's path with ``runner`` as the callback; periodic checkpoints are saves.
        Raises :class:`Stopped` (after writing the checkpoint) when the runner stops the run."""
        options, span = path_request(self.case)
        p = self.case["path"]
        friction = p.get("parameter", "alpha") == "friction"
        if self.resume is not None:
            self.check_system(system)
        system.check_positive_definite()
        solver = select_solver(system, *(("exact", "condensed") if friction else (p["method"], p["backend"])))
        runner.begin(solver, self.resume["path"] if self.resume else None)
        try:
            stepper = (_friction_stepper(system, p, options, solver, self.resume, runner.on_start) if friction else
                       path_stepper(system, span, options, p["method"], solver=solver, resume=self.resume,
                                    monitor=runner.on_start))
        except StartInterrupted as exc:
            runner.display.clear()
            raise Stopped(f"{runner.reason} while reaching the start ({exc.progress.transitions} transition(s) of "
                          f"its homotopy)", interrupted=runner.interrupted, resumable=False, checkpoint=False) from None

        def save(path, state):
            runner.display.clear()
            save_checkpoint(self.partial, path, self.case, "checkpoint", state, self.replace)
            runner.checkpoint_saved()

        t = time.perf_counter()
        try:
            path = stepper.run(runner.on_point, save)
        except KeyboardInterrupt:
            if has_checkpoint(self.partial):
                raise Stopped("aborted (Ctrl-C twice); the last periodic checkpoint remains", interrupted=True) \
                    from None
            raise
        if path.status == "stopped by callback" and runner.reason is not None:
            runner.display.clear()
            save_checkpoint(self.partial, path, self.case, runner.reason, path.resume_state, self.replace)
            raise Stopped(runner.reason, interrupted=runner.interrupted, resumable=path.resume_state is not None)
        self.timings["trace"] = time.perf_counter() - t
        runner.end(path)
        t = time.perf_counter()
        save_traced(self.partial, path, self.case, self.replace)
        self.timings["checkpoint"] = time.perf_counter() - t
        if runner.interrupted:  # Ctrl-C while the traced path was saved
            raise Stopped("interrupted (Ctrl-C) after tracing; the outputs are not written", interrupted=True)
        return path

    def finish(self, path, warn: Callable = log.warning, system=None, interrupted: Optional[Callable] = None) -> list:
        """Write the outputs into ``<out>.partial/``, drop the checkpoint, rename it to ``<out>/``.
        ``interrupted``: a callable asked between the outputs and before the checkpoint is dropped
        (a Ctrl-C held back while a library such as VTK ran); when it answers True the writing
        stops with KeyboardInterrupt and the checkpoint is kept."""
        saved = os.path.join(self.partial, CHECKPOINT_DIRS[0], "path")
        files = write_outputs(path, self.case, self.partial, self.timings, warn, system,
                              saved=saved if self._traced_checkpoint() else None, interrupted=interrupted)
        _go_on(interrupted)
        for name in CHECKPOINT_DIRS:
            shutil.rmtree(os.path.join(self.partial, name), ignore_errors=True)
        if os.path.isdir(self.out):
            old = self.out + ".old"
            shutil.rmtree(old, ignore_errors=True)
            os.rename(self.out, old)
            os.rename(self.partial, self.out)
            shutil.rmtree(old)
        else:
            os.rename(self.partial, self.out)
        return files

    def check_system(self, system):
        """CaseError when the resumed checkpoint belongs to another system (its checksum)."""
        saved = self.resume["path"].system_checksum
        if saved is not None and saved != system.checksum():
            raise CaseError(f"the checkpoint in {self.partial!r} belongs to another system (checksum {saved[:12]}..., "
                            f"this case's model {system.checksum()[:12]}...): it was written by another case or "
                            f"another cfcontact; start over with --force")

    def _checkpoint_replaces(self) -> bool:
        """Was the stopped run in ``<out>.partial/`` started with --force (its state.json's "replace")?"""
        for name in CHECKPOINT_DIRS:
            try:
                return bool(read_json(os.path.join(self.partial, name, "state.json")).get("replace"))
            except (OSError, ValueError, AttributeError):
                continue
        return False

    def _traced_checkpoint(self) -> bool:
        try:
            return bool(read_json(os.path.join(self.partial, CHECKPOINT_DIRS[0], "state.json")).get("traced"))
        except (OSError, ValueError, AttributeError):
            return False

    def abandon(self, interrupted: bool = False) -> bool:
        """After a failure or an interrupt: keep only the checkpoint in ``<out>.partial/`` (True),
        or remove the folder when this run made it or started over (False).  The checkpoint of a
        traced path is kept after an interrupt only: a failure while writing the outputs would
        fail again on resuming."""
        if has_checkpoint(self.partial) and (interrupted or not self._traced_checkpoint()):
            for name in os.listdir(self.partial):
                if name not in CHECKPOINT_DIRS:
                    _remove(os.path.join(self.partial, name))
            return True
        if self.created or not self.resuming or self._traced_checkpoint():
            shutil.rmtree(self.partial, ignore_errors=True)
        return False


# ============================================================ saved paths
def _friction_stepper(system, p, options, solver, resume, monitor=None):
    """[path] parameter = "friction": the stepper of :mod:`cfcontact.friction`."""
    from cfcontact.friction import friction_stepper

    return friction_stepper(system, p["alpha_start"], p["friction_start"], p["friction_end"], p["method"], options,
                            solver, resume, monitor)


def load_saved_path(dirname) -> SolutionPath:
    """A saved path whichever its parameter (a friction path: :class:`cfcontact.friction.FrictionPath`)."""
    from cfcontact.friction import load_path

    return load_path(dirname)


def parameter_label(path) -> str:
    """The x label of a path's plots: "α", or "F" for a path over the friction coefficient."""
    return "α" if path.parameter_name == "alpha" else path.parameter_name


def resolve_saved(dirname) -> str:
    """The path/ folder of a saved path, a run output folder, or a stopped run's <out>.partial folder."""
    dirname = os.fspath(dirname)
    for cand in (dirname, os.path.join(dirname, "path"), os.path.join(dirname, CHECKPOINT_DIRS[0], "path")):
        if os.path.isfile(os.path.join(cand, "path.json")):
            return cand
    raise CaseError(f"{dirname!r} is not a saved path (expected path.json in it, in path/ or in checkpoint/path/)")


def run_timings(src):
    """The ``timings`` of the run whose output folder holds the saved path ``src`` (``<out>/path``:
    its ``summary.json``), or None (a stopped run's or a library's saved path)."""
    folder = os.path.dirname(os.path.abspath(src))
    if not holds_format(folder, "summary.json", RUN_FORMAT):
        return None
    try:
        timings = read_json(os.path.join(folder, "summary.json")).get("timings")
    except (OSError, ValueError, AttributeError) as exc:
        log.warning("%s is unreadable (%s): the run's timings are not shown", os.path.join(folder, "summary.json"), exc)
        return None
    return timings if isinstance(timings, dict) else None


def saved_material(src, path):
    """The material of a saved path: stored with its geometry, else the [material] of the run's case.toml
    (paths saved before the material was stored); CaseError if neither is there."""
    material = getattr(path.geometry, "material", None)
    if material is not None:
        return material
    folder = os.path.abspath(src)
    # <out>/path -> <out>/case.toml; <out>.partial/checkpoint/path -> <out>.partial/case.toml
    for cand in (os.path.dirname(folder), os.path.dirname(os.path.dirname(folder))):
        fn = os.path.join(cand, "case.toml")
        if os.path.isfile(fn):
            try:
                with open(fn, "rb") as fh:
                    mat = tomllib.loads(fh.read().decode("utf-8")).get("material", {})
            except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError):
                continue
            return {key: mat.get(key, default) for key, default in DEFAULT_MATERIAL.items()}
    raise CaseError(f"{src!r} stores no material (saved by an older cfcontact) and no case.toml is next to it; "
                    f"re-run the case to get stresses")
