"""Runs ``python -m cfcontact.meshes.arc_on_block`` (the script moved into the package): kept so that
``python3 meshes/arc_on_block.py out.msh ...`` still works where cfcontact is installed."""

import runpy

if __name__ == "__main__":
    runpy.run_module("cfcontact.meshes.arc_on_block", run_name="__main__", alter_sys=True)
