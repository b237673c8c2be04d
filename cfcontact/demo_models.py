"""The models of the main demo and of the benchmark, shared by ``demos/``, :mod:`cfcontact.bench`
and the tests (the numbers live here once).

* The main demo (``demos/main.py``): a steel block (E = 2.1e11 Pa, nu = 0.3) on a soft layer 0.3
  thick (E = 2.1e8 Pa, nu = 0, a cork-like material), 3 long, both clamped on their left edges,
  30 x 10 cells per body, each quadrilateral split into two triangles: n = 1320, m = 30
  (:data:`DEMO_MODEL`, loads :data:`DEMO_F1`, :data:`DEMO_F2`, :data:`DEMO_BODY_FORCE1`,
  :data:`DEMO_BODY_FORCE2`; :func:`build_demo`).  Why this one: folds need friction above the
  model's critical value (demos/critical_friction.py), and the two steel blocks of the earlier
  demo (height2 = 0.5, quadrilaterals) cannot fold below F ~ 1.9, so they cannot show the seed's
  three solutions at F = 0.6; on a soft layer with nu = 0 normal and tangential contact
  displacements couple strongly and two neighbouring nodes slipping in opposite directions fold
  from F ~ 0.56 on.
* The second model of the benchmark's Part A and the model of its Part B: two steel blocks
  (:data:`BLOCKS_MODEL`, body 2 half as high as body 1, quadrilaterals, clamped on their left
  edges; n = 1320, m = 30 on 30 x 10 cells per block) with the loads of the earlier main demo
  (:data:`BLOCKS_F1`, :data:`BLOCKS_F2`; :func:`build_blocks`).  All its contact nodes work along
  the path (F = 30: 59 transitions, 4 folds, 5 solutions), where the main demo's path moves a few
  nodes near the ends of the interface (5 to 10 transitions): the speed-up of the exact method
  grows with the number of transitions, since its set-up (one factorization of K and S) is paid
  once.

Importing this module imports no FEM code; the builders do.
"""

from __future__ import annotations

STEEL = 2.1e11
DEMO_MODEL = dict(height=1.0, height2=0.3, length=3.0, cell="triangle",
                  E={"body1": STEEL, "body2": STEEL / 1000}, nu={"body1": 0.3, "body2": 0.0})

# The load path f(alpha) = (1 - alpha) f1 + alpha f2: tractions [Pa] on the tagged edges (a
# uniform part per edge, plus four windows of one element edge each: on top1 at x in [2.2, 2.3]
# and [2.9, 3.0], on bottom2 at x in [2.5, 2.6] and [2.9, 3.0]) and body forces [N/m^3].  The
# numbers come from a search: a linear program put nodes 27 and 28 into the load cone of three
# solutions at F = 0.6, then random and local searches over the 16 load terms chose f1, f2 so
# that the predictor-corrector of [JL-PF] and the exact method give the same transitions at all three
# F; rounded to three digits.  The outcome per F is printed by the demo and checked by
# tests/test_demos.py.  The three-solution interval at F = 0.6 is narrow (2.7e-3 in alpha,
# around alpha = 0.792): changing a load term by 0.1 % can remove it.
DEMO_F1 = {"top1": [(-1.48e4, 9.20e3), {"value": (0.0, -3.49e5), "x": (2.2, 2.3)},
                    {"value": (-1.55e5, 0.0), "x": (2.9, 3.0)}],
           "right1": (-2.10e5, 1.78e4),
           "bottom2": [(-3.73, 0.172), {"value": (811.0, 0.0), "x": (2.5, 2.6)},
                       {"value": (-367.0, 0.0), "x": (2.9, 3.0)}],
           "right2": (805.0, -1.19)}
DEMO_F2 = {"top1": [(3.91e3, -2.43e3), {"value": (0.0, 6.11e5), "x": (2.2, 2.3)},
                    {"value": (1.31e6, 0.0), "x": (2.9, 3.0)}],
           "right1": (5.55e4, -4.71e3),
           "bottom2": [(0.987, -0.0455), {"value": (669.0, 0.0), "x": (2.5, 2.6)},
                       {"value": (-604.0, 0.0), "x": (2.9, 3.0)}],
           "right2": (-213.0, 0.315)}
DEMO_BODY_FORCE1 = {"body1": (-6.81e4, -2.95e3), "body2": (141.0, 0.257)}
DEMO_BODY_FORCE2 = {"body1": (1.80e4, 780.0), "body2": (-37.2, -0.0679)}
#: The seed's three kinds of friction coefficient: single-valued, three solutions, many folds.
DEMO_FRICTIONS = (0.1, 0.6, 30.0)
DEMO_ALPHA = (0.0, 1.0)

BLOCKS_MODEL = dict(height=1.0, height2=0.5, length=3.0)
BLOCKS_F1 = {"top1": (-5.734e7, 3.658e6), "right1": (3.910e7, -8.724e7), "bottom2": (1.877e8, -1.500e6)}
BLOCKS_F2 = {"top1": (1.0e8, 0.0), "right2": (-5.807e7, 1.510e3), "bottom2": (-1.045e8, 1.450e8)}


def build_demo(friction, comm=None):
    """The main demo's contact system for friction coefficient ``friction``."""
    from cfcontact.models import two_blocks

    return two_blocks(friction=friction, tractions1=DEMO_F1, tractions2=DEMO_F2,
                      body_force1=DEMO_BODY_FORCE1, body_force2=DEMO_BODY_FORCE2, comm=comm, **DEMO_MODEL)


def build_blocks(friction, nx=30, ny=10, quick=False):
    """The two steel blocks (BLOCKS_MODEL, BLOCKS_F1, BLOCKS_F2); ``quick``: 12 x 4 cells per block."""
    from cfcontact.models import two_blocks

    if quick:
        nx, ny = 12, 4
    return two_blocks(nx=nx, ny=ny, friction=friction, tractions1=BLOCKS_F1, tractions2=BLOCKS_F2, **BLOCKS_MODEL)
