"""Runs ``python -m cfcontact.meshes.cylinder_on_block``: kept so that ``python3 meshes/cylinder_on_block.py out.msh ...``
works where cfcontact is installed, like the other scripts of this folder."""

import runpy

if __name__ == "__main__":
    runpy.run_module("cfcontact.meshes.cylinder_on_block", run_name="__main__", alter_sys=True)
