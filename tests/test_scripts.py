"""Every script in scripts/ still runs, and scripts/README.md lists exactly
the scripts there.

Each script's `--help` runs its imports and builds its parser, so a renamed
or moved function it uses fails here. The scripts share most of their
imports (torch, the package), so one subprocess runs them all in turn, each
as `__main__` in a fresh namespace (~4 CPU-s, where a process each costs
~30): one failing script's traceback is recorded and the rest still run."""

import json
import re
import subprocess
import sys

import pytest
from conftest import REPO

SCRIPTS = REPO / "scripts"
PY_SCRIPTS = sorted(p.name for p in SCRIPTS.glob("*.py"))

RUNNER = """
import contextlib, io, json, runpy, sys, traceback
scripts, out = sys.argv[1], sys.argv[2]
sys.path.insert(0, scripts)
results = {}
for name in sys.argv[3:]:
    buf = io.StringIO()
    sys.argv = [f"{scripts}/{name}", "--help"]
    code = None
    with contextlib.redirect_stdout(buf), contextlib.redirect_stderr(buf):
        try:
            runpy.run_path(f"{scripts}/{name}", run_name="__main__")
        except SystemExit as exc:
            code = exc.code
        except BaseException:
            traceback.print_exc()
            code = "raised"
    results[name] = {"code": code, "output": buf.getvalue()[-4000:]}
with open(out, "w") as f:
    json.dump(results, f)
"""


@pytest.fixture(scope="module")
def helps(tmp_path_factory):
    """{script: {"code": its exit status, "output": what it printed}} for every `scripts/*.py --help`."""
    out = tmp_path_factory.mktemp("scripts") / "helps.json"
    proc = subprocess.run([sys.executable, "-c", RUNNER, str(SCRIPTS), str(out), *PY_SCRIPTS], capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr[-4000:]
    return json.loads(out.read_text())


@pytest.mark.parametrize("name", PY_SCRIPTS)
def test_help_runs(helps, name):
    result = helps[name]
    assert result["code"] in (0, None) and "usage:" in result["output"], result["output"]


def test_readme_lists_every_script():
    """The index's tables name each script in their first column, once."""
    listed = re.findall(r"^\| `([^`]+)` \|", (SCRIPTS / "README.md").read_text(), re.M)
    present = sorted(p.name for p in SCRIPTS.iterdir() if p.is_file() and p.name != "README.md")
    assert sorted(listed) == present
