"""The stepper interface of the path-following methods.

A stepper owns one run of a method on a live :class:`~cfcontact.solution_path.SolutionPath`.
:meth:`Stepper.run` advances it point by point and hands every accepted point to a callback,
whose answer decides what happens next:

* falsy: continue;
* :data:`CHECKPOINT`: call ``save(path, resume_state)`` with the live path (its ``stats`` up to
  date) and the state that continues it (``trace_path(resume={"path": ..., "state": ...})``),
  then continue -- a checkpoint is a save, the run is not stopped;
* anything else truthy: stop there (status "stopped by callback", ``path.resume_state`` set).

:class:`cfcontact.seed.SeedStepper` and :class:`cfcontact.exact.ExactStepper` advance one
accepted point at a time (a step, a transition) and their resume state is always current.

Before the first point there may be a long start (the exact method's homotopies from the
frictionless solution or the all-open state when SSNM does not converge at alpha_start): a
``monitor`` given to the stepper sees its progress (:class:`StartProgress`) and can abandon it.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Callable, Optional

from cfcontact.errors import InputError


@dataclass(frozen=True)
class StartProgress:
    """What a run's ``monitor`` sees while the start is being reached, before the path has a point:
    ``stage`` (the exact method's start: "frictionless", its homotopy from the frictionless
    solution, or "homotopy", from the all-open state, which follows when the first does not reach
    t = 1), the transitions traced so far (of both), the homotopy parameter ``t`` (from 0; the
    start is reached at 1; the frictionless homotopy can pass below 0 between folds) and the
    seconds since the stage began.  The monitor's truthy answer abandons the run
    (:class:`~cfcontact.errors.StartInterrupted`)."""

    stage: str
    transitions: int
    t: float
    elapsed: float


def check_monitor(monitor):
    """InputError unless ``monitor`` is None or a callable (it is called with a StartProgress)."""
    if monitor is not None and not callable(monitor):
        raise InputError(f"monitor must be a function of a StartProgress (or None), got {monitor!r}")


class _Checkpoint:
    """The callback's answer "save a checkpoint and go on" (a singleton)."""

    def __repr__(self):
        return "CHECKPOINT"


#: Returned by a callback of :meth:`Stepper.run`: save a checkpoint and continue.
CHECKPOINT = _Checkpoint()


class Stepper:
    """Base class: :meth:`run` over :meth:`advance`; subclasses set ``path``, ``solver`` and the
    bookkeeping of :meth:`_start_clock` and implement :meth:`_step`, :meth:`_finish`,
    :meth:`point`, :attr:`resume_state` and :meth:`stop`."""

    method = ""
    path = None
    solver = None
    finished = False  # the run has ended (advance returns None from now on)
    done = False  # the last accepted point ended the path: the next advance finishes it "completed"
    _pending_point = None  # index of an accepted point not handed out yet (the start point), or None
    callback = None  # the callback of :meth:`run` (work after the run's end, e.g. a tree's, may be stopped by it)

    def _start_clock(self, before: Optional[dict] = None):
        """Counters of this run start now; ``before``: the stats of the stopped run it continues."""
        self._t0 = time.perf_counter()
        self._stats0 = self.solver.stats.as_dict()
        self._before = {k: v for k, v in (before or {}).items() if isinstance(v, (int, float))}

    def _update_stats(self):
        """path.stats = the solver's work since :meth:`_start_clock` plus that of the runs before."""
        st, before = self.solver.stats.as_dict(), self._before
        self.path.stats = {k: st[k] - self._stats0.get(k, 0) + before.get(k, 0) for k in st}
        self.path.stats["wall_time"] = time.perf_counter() - self._t0 + before.get("wall_time", 0.0)

    def advance(self) -> Optional[int]:
        """Index of the next accepted point of the path, or None when the run has ended."""
        if self.finished:
            return None
        if self._pending_point is not None:
            index, self._pending_point = self._pending_point, None
            return index
        if self.done:
            self._finish("completed")
            return None
        return self._step()

    def _step(self) -> Optional[int]:
        """The method's own step: index of the next accepted point, or None (after :meth:`_finish`)."""
        raise NotImplementedError

    def _finish(self, status):
        """End the run with ``status``; returns the path."""
        raise NotImplementedError

    def point(self, index: int):
        """The :class:`~cfcontact.solution_path.PathPoint` of an accepted point (for callbacks)."""
        raise NotImplementedError

    @property
    def resume_state(self) -> dict:
        """What continues the run after the last accepted point (JSON-able)."""
        raise NotImplementedError

    def stop(self):
        """End the run at the last accepted point: status "stopped by callback"; returns the path."""
        raise NotImplementedError

    def run(self, callback: Optional[Callable] = None, save: Optional[Callable] = None):
        """Advance to the end (or until the callback stops the run); returns the path."""
        self.callback = callback
        while True:
            index = self.advance()
            if index is None:
                return self.path
            if callback is None:
                continue
            action = callback(self.point(index))
            if action is CHECKPOINT:
                if save is not None:
                    self._update_stats()
                    save(self.path, self.resume_state)
            elif action:
                return self.stop()


def stop_only(callback: Optional[Callable]) -> Optional[Callable]:
    """``callback`` for work that cannot be checkpointed or resumed (sub-runs after a run's end):
    its answer stops that work when it is a stop, and :data:`CHECKPOINT` counts as "go on"."""
    if callback is None:
        return None

    def answer(point):
        action = callback(point)
        return bool(action) and action is not CHECKPOINT

    return answer
