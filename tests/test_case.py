"""Case files (cfcontact.case): the schema is the one source of the format, the [path] options
reach the library, the reference in docs/cli.md is the schema's."""

import os
import subprocess
import sys
import tomllib

import pytest

from cfcontact import case
from cfcontact.options import PathOptions

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def test_reference_is_a_valid_case_and_documents_every_key():
    text = case.reference_text()
    checked = case.validate_case(tomllib.loads(text))
    assert checked["geometry"]["kind"] == "two_blocks" and checked["path"]["method"] == "seed"
    for section, keys in case.SCHEMA.items():
        for name in keys or case.BLOCK_GEOMETRY:
            assert f"{name} =" in text or f"# {name} " in text or f"[{section}.{name}]" in text, (section, name)
    for name in PathOptions.names():  # generated from the options dataclass
        assert name in case.SCHEMA["path"]


def test_docs_hold_the_generated_reference():
    with open(os.path.join(ROOT, "docs", "cli.md")) as fh:
        docs = fh.read()
    assert "```toml\n" + case.reference_text() + "```\n" in docs, "docs/cli.md: rerun the reference (cfcontact schema)"


@pytest.mark.slow
def test_schema_command_prints_the_reference():
    env = dict(os.environ, PYTHONPATH=ROOT + os.pathsep + os.environ.get("PYTHONPATH", ""))
    proc = subprocess.run([sys.executable, "-m", "cfcontact", "schema"], capture_output=True, text=True, env=env,
                          cwd=ROOT, timeout=120)
    assert proc.returncode == 0 and proc.stdout == case.reference_text()


def test_every_path_option_reaches_the_request():
    raw = {"geometry": {"kind": "two_blocks"},
           "path": {"method": "exact", "alpha_start": 1.0, "alpha_end": 0.0, "tie_rtol": 1e-9, "h_min": 1e-6,
                    "max_transitions": 7, "alpha_min": -0.5}}
    options, span = case.path_request(case.validate_case(raw))
    assert options == PathOptions(tie_rtol=1e-9, h_min=1e-6, max_transitions=7, alpha_min=-0.5)
    assert (span.start, span.end, span.lo, span.hi) == (1.0, 0.0, -0.5, 1.0)


@pytest.mark.parametrize("path,words", [
    ({"tie_rtol": 0.5}, ["[path]", "tie_rtol", "0.5"]),
    ({"tie_rtol": "small"}, ["[path] tie_rtol", "number", "string"]),
    ({"alpha_start": 2.0, "alpha_max": 1.5}, ["[path]", "alpha_start=2.0", "outside"]),
    ({"alpha_min": 0.5, "alpha_max": 0.5}, ["[path]", "empty"]),
])
def test_bad_path_options_name_the_key(path, words):
    with pytest.raises(case.CaseError) as info:
        case.validate_case({"geometry": {"kind": "two_blocks"}, "path": path})
    for w in words:
        assert w in str(info.value), (w, str(info.value))
