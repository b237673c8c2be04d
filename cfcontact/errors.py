"""Typed exceptions of cfcontact.

Every error that a user can provoke with bad input is a subclass of
:class:`CfcontactError`, so ``except cfcontact.CfcontactError`` catches them all.
Messages name the bad value and what would be valid.
"""

from __future__ import annotations


class CfcontactError(Exception):
    """Base class of every cfcontact error."""


class InputError(CfcontactError, ValueError):
    """Bad user input: a wrong shape, a negative friction coefficient, an unknown tag..."""


class GeometryError(InputError):
    """A mesh or geometry that cannot be used (unknown tag, non-matching interface...)."""


class SingularSystemError(CfcontactError):
    """A linear system could not be factored (e.g. K singular: too few Dirichlet conditions)."""


class NotPositiveDefiniteError(SingularSystemError, InputError):
    """The stiffness K is not positive definite on the free DOFs (negative eigenvalues: a sign
    error, a negative modulus...); not the same as singular (zero eigenvalues, too few Dirichlet
    conditions), which is a :class:`SingularSystemError`.

    Attributes
    ----------
    inertia : tuple
        (negative, zero, positive) eigenvalue counts of K, from its factorization.
    """

    def __init__(self, message, inertia=None):
        super().__init__(message)
        self.inertia = inertia


class ConvergenceError(CfcontactError):
    """The semi-smooth Newton method did not converge.

    Attributes
    ----------
    iterations : int
        Iterations performed.
    last : object
        The last iterate (a :class:`cfcontact.Solution`), for inspection.
    """

    def __init__(self, message, iterations=None, last=None):
        super().__init__(message)
        self.iterations = iterations
        self.last = last


class PathError(CfcontactError):
    """A path-following run could not proceed (see the attached event)."""

    def __init__(self, message, event=None):
        super().__init__(message)
        self.event = event


class StartInterrupted(PathError):
    """A run's monitor stopped it while its start was still being reached (the exact method's
    homotopy start can take many transitions before the path has its first point); nothing to
    resume: the path has no point yet.

    Attributes
    ----------
    progress : object
        The last :class:`cfcontact.StartProgress` the monitor saw.
    """

    def __init__(self, message, progress=None):
        super().__init__(message)
        self.progress = progress


class EnumerationTooLarge(InputError):
    """Exhaustive enumeration refused because the problem is too large."""


class PairingWarning(UserWarning):
    """Contact pairing left some slave nodes out (their normal misses the master, meets only its
    back, or meets no front of it within the search distance).  Not an error: the model is built."""


class IgnoredOptionWarning(UserWarning):
    """An option given explicitly that is not used: a path option the chosen method does not use
    (``tree=True`` with ``method="seed"``, a seed step option with ``method="exact"``), body 2's
    mesh with ``two_blocks(foundation=True)``.  The run goes on without it."""


class MeshWarning(UserWarning):
    """Something in a mesh that is valid but rarely meant: a body made of pieces that share no node
    while some of their nodes coincide (surfaces meshed without being joined).  The model is built."""
