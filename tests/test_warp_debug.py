"""The bounds-checked kernel subset: every test marked ``warp_debug`` (every kernel at least once, on every store
kind) run again in a subprocess with Warp's debug mode, where an index past an array's end stops the process."""

import subprocess
import sys
from pathlib import Path

import pytest

TESTS = Path(__file__).resolve().parent


def test_marked_subset_passes_bounds_checked(request):
    """`pytest --warp-debug -m warp_debug` passes; on failure the message names the last kernel launched."""
    if request.config.getoption("--warp-debug"):
        pytest.skip("this session is the bounds-checked run already")
    proc = subprocess.run([sys.executable, "-m", "pytest", "-q", "-x", "-p", "no:cacheprovider", "--warp-debug",
                           "-m", "warp_debug", str(TESTS)], capture_output=True, text=True, timeout=3600,
                          cwd=TESTS.parent)
    if proc.returncode != 0:
        launches = [line for line in proc.stderr.splitlines() if line.startswith("[warp-debug] launch")]
        last = launches[-1].split("launch ", 1)[1] if launches else "(none)"
        tail = "\n".join((proc.stdout + proc.stderr).splitlines()[-40:])
        pytest.fail(f"bounds-checked subset failed (exit {proc.returncode}); last kernel launched: {last}\n{tail}")
    assert " passed" in proc.stdout
