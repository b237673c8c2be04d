"""Runs ``python -m cfcontact.meshes.two_blocks`` (the script moved into the package): kept so that
``python3 meshes/two_blocks.py out.msh ...`` still works where cfcontact is installed."""

import runpy

if __name__ == "__main__":
    runpy.run_module("cfcontact.meshes.two_blocks", run_name="__main__", alter_sys=True)
