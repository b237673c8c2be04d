"""The gmsh geometry scripts of the built-in models (gmsh only, no dolfinx).

Each module builds its model into the current gmsh model (``build(...)``) and runs as a script
that writes a ``.msh`` file, e.g. ``python -m cfcontact.meshes.two_blocks out.msh --nx 30``:

* :mod:`cfcontact.meshes.common` -- the tag convention (:data:`~cfcontact.meshes.common.TAGS`)
  and the parameter checks shared by the scripts;
* :mod:`cfcontact.meshes.two_blocks` -- two stacked blocks (also inclined, or one block on a
  rigid foundation);
* :mod:`cfcontact.meshes.arc_on_block` -- a body with a convex arc bottom in a matching seat;
* :mod:`cfcontact.meshes.cylinder_on_block` -- a (half-)cylinder pressed on a block (Hertz), the
  bodies meshed independently, mirror-symmetric or a half model;
* :mod:`cfcontact.meshes.rounded_punch` -- a flat punch with rounded edges on a block (likewise).
"""
