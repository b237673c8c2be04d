"""cfcontact: path following for 2D static contact with Coulomb friction (FEniCSx + PETSc).

Importing cfcontact never imports dolfinx: the FEM layer (:func:`two_blocks`,
:func:`assemble_contact_system`) is loaded when first used.
"""

from cfcontact.errors import (
    CfcontactError,
    ConvergenceError,
    EnumerationTooLarge,
    GeometryError,
    InputError,
    PairingWarning,
    PathError,
    SingularSystemError,
)
from cfcontact.ssnm import (
    DirNeuSolver,
    InactiveSets,
    Solution,
    SolverOptions,
    dirneu,
    get_solver,
    inactive_sets,
    is_fixed_point,
    ssnm,
    verify,
)
from cfcontact.system import ContactGeometry, ContactSystem

__version__ = "0.1.0"

_LAZY = {
    "two_blocks": ("cfcontact.models", "two_blocks"),
    "arc_on_block": ("cfcontact.models", "arc_on_block"),
    "cylinder_on_block": ("cfcontact.models", "cylinder_on_block"),
    "rounded_punch": ("cfcontact.models", "rounded_punch"),
    "assemble_contact_system": ("cfcontact.assembly", "assemble_contact_system"),
    "trace_path": ("cfcontact.path", "trace_path"),
    "SolutionPath": ("cfcontact.solution_path", "SolutionPath"),
    "PathOptions": ("cfcontact.options", "PathOptions"),
    "enumerate_solutions": ("cfcontact.enumerate", "enumerate_solutions"),
    "critical_friction": ("cfcontact.critical", "critical_friction"),
    "one_node": ("cfcontact.lumped", "one_node"),
    "trace_exact": ("cfcontact.exact", "trace_exact"),
    "follow_alternative": ("cfcontact.exact", "follow_alternative"),
    "CondensedSolver": ("cfcontact.condensed", "CondensedSolver"),
    # issue #16: friction as the parameter
    "trace_friction_path": ("cfcontact.friction", "trace_friction_path"),
    "FrictionPath": ("cfcontact.friction", "FrictionPath"),
    "critical_friction_path": ("cfcontact.fmap", "critical_friction_path"),
    "multiplicity_map": ("cfcontact.fmap", "multiplicity_map"),
    "fold_curves": ("cfcontact.fmap", "fold_curves"),
}


def __getattr__(name):
    if name in _LAZY:
        import importlib

        module, attr = _LAZY[name]
        return getattr(importlib.import_module(module), attr)
    raise AttributeError(f"module 'cfcontact' has no attribute {name!r}")


__all__ = [
    "CfcontactError", "ConvergenceError", "EnumerationTooLarge", "GeometryError", "InputError", "PairingWarning",
    "PathError",
    "SingularSystemError", "DirNeuSolver", "InactiveSets", "Solution", "SolverOptions", "dirneu", "get_solver",
    "inactive_sets", "is_fixed_point", "ssnm", "verify", "ContactGeometry", "ContactSystem", *_LAZY,
]
