"""Runs ``python -m cfcontact.meshes.rounded_punch``: kept so that ``python3 meshes/rounded_punch.py out.msh ...``
works where cfcontact is installed, like the other scripts of this folder."""

import runpy

if __name__ == "__main__":
    runpy.run_module("cfcontact.meshes.rounded_punch", run_name="__main__", alter_sys=True)
