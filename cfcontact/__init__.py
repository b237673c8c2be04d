"""cfcontact: path following for 2D static contact with Coulomb friction (FEniCSx + PETSc).

Importing cfcontact loads only its exceptions: every other name (the solver layer with PETSc,
the FEM layer with dolfinx: :func:`two_blocks`, :func:`assemble_contact_system`) is loaded when
first used, so ``python -m cfcontact`` reaches its own code (and its Ctrl-C handling) at once.
"""

import sys
import types

from cfcontact.errors import (
    CfcontactError,
    ConvergenceError,
    EnumerationTooLarge,
    GeometryError,
    IgnoredOptionWarning,
    InputError,
    MeshWarning,
    NotPositiveDefiniteError,
    PairingWarning,
    PathError,
    SingularSystemError,
    StartInterrupted,
)

__version__ = "0.1.0"

_LAZY = {
    **{name: ("cfcontact.ssnm", name) for name in (
        "DirNeuSolver", "InactiveSets", "Solution", "SolverOptions", "dirneu", "get_solver", "inactive_sets",
        "is_fixed_point", "ssnm", "verify")},
    "ContactGeometry": ("cfcontact.system", "ContactGeometry"),
    "ContactSystem": ("cfcontact.system", "ContactSystem"),
    "two_blocks": ("cfcontact.models", "two_blocks"),
    "arc_on_block": ("cfcontact.models", "arc_on_block"),
    "cylinder_on_block": ("cfcontact.models", "cylinder_on_block"),
    "rounded_punch": ("cfcontact.models", "rounded_punch"),
    "assemble_contact_system": ("cfcontact.assembly", "assemble_contact_system"),
    "trace_path": ("cfcontact.path", "trace_path"),
    "SolutionPath": ("cfcontact.solution_path", "SolutionPath"),
    "PathOptions": ("cfcontact.options", "PathOptions"),
    "StartProgress": ("cfcontact.stepper", "StartProgress"),
    "enumerate_solutions": ("cfcontact.enumerate", "enumerate_solutions"),
    "critical_friction": ("cfcontact.critical", "critical_friction"),
    "one_node": ("cfcontact.lumped", "one_node"),
    "trace_exact": ("cfcontact.exact", "trace_exact"),
    "follow_alternative": ("cfcontact.exact", "follow_alternative"),
    "CondensedSolver": ("cfcontact.condensed", "CondensedSolver"),
    # friction as the parameter
    "trace_friction_path": ("cfcontact.friction", "trace_friction_path"),
    "FrictionPath": ("cfcontact.friction", "FrictionPath"),
    "critical_friction_path": ("cfcontact.fmap", "critical_friction_path"),
    "multiplicity_map": ("cfcontact.fmap", "multiplicity_map"),
    "fold_curves": ("cfcontact.fmap", "fold_curves"),
}


class _Package(types.ModuleType):
    """The package object: ``cfcontact.ssnm`` stays the function ``ssnm`` (as it was when this
    module imported it eagerly), also after the submodule :mod:`cfcontact.ssnm` is imported
    (the import system then sets the package attribute ``ssnm`` to the module)."""

    def __setattr__(self, name, value):
        if name == "ssnm" and isinstance(value, types.ModuleType) and hasattr(value, "ssnm"):
            value = value.ssnm
        super().__setattr__(name, value)


sys.modules[__name__].__class__ = _Package


def __getattr__(name):
    if name in _LAZY:
        import importlib

        module, attr = _LAZY[name]
        return getattr(importlib.import_module(module), attr)
    raise AttributeError(f"module 'cfcontact' has no attribute {name!r}")


__all__ = [
    "CfcontactError", "ConvergenceError", "EnumerationTooLarge", "GeometryError", "IgnoredOptionWarning", "InputError", "MeshWarning",
    "NotPositiveDefiniteError", "PairingWarning", "PathError", "SingularSystemError",
    "StartInterrupted", *_LAZY,
]
