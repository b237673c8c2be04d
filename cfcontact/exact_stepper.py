"""Adapter: the exact method (:mod:`cfcontact.exact`) behind the stepper interface.

:func:`cfcontact.exact.run_exact` follows the path in one callback-driven loop, so it cannot
hand out its points one by one.  :class:`ExactStepper` gives it the interface of
:class:`cfcontact.stepper.Stepper` anyway: a callback answer that stops the run stops it, and a
:data:`~cfcontact.stepper.CHECKPOINT` answer is carried out by stop and resume -- the run stops at
that point (exact.py then forms its resume state), ``save(path, path.resume_state)`` is called,
and the run goes on with ``run_exact(resume=...)``, which rebuilds the method's context (its cache
of candidate branches is lost; the backend, with its factorization of K, is kept).  The result
equals an uninterrupted run (the tests check it).

This module is temporary: when the exact method becomes a stepper whose resume state is always
current (like :class:`cfcontact.seed.SeedStepper`), it replaces this class, and a checkpoint
becomes a plain save.
"""

from __future__ import annotations

from typing import Callable, Optional

from cfcontact.exact import run_exact
from cfcontact.options import AlphaSpan, PathOptions
from cfcontact.stepper import CHECKPOINT, Stepper


class ExactStepper(Stepper):
    """The exact method as a stepper, by stop and resume (see the module docstring)."""

    method = "exact"

    def __init__(self, system, span: AlphaSpan, options: PathOptions, solver=None, y0=None, resume=None):
        self.system, self.span, self.opts, self.solver = system, span, options, solver
        self.y0, self._resume = y0, resume
        self.path = None

    def run(self, callback: Optional[Callable] = None, save: Optional[Callable] = None):
        resume = self._resume
        while True:
            answer = []

            def relay(point):
                action = callback(point)
                if action:
                    answer.append(action)
                return bool(action)

            path = run_exact(self.system, self.span, self.opts, self.solver, y0=self.y0, resume=resume,
                             callback=None if callback is None else relay)
            self.path = path
            if path.status != "stopped by callback" or not answer or answer[0] is not CHECKPOINT:
                return path
            if save is not None:
                save(path, path.resume_state)
            resume = {"path": path, "state": path.resume_state}
