"""The bounds-checked kernel subset: every test marked ``warp_debug`` (every kernel at least once, on every store
kind) run again in a subprocess with Warp's debug mode, where an index past an array's end stops the process."""

import os
import subprocess
import sys
from pathlib import Path

import pytest

TESTS = Path(__file__).resolve().parent


def test_marked_subset_passes_bounds_checked(request, tmp_path):
    """`pytest --warp-debug -m warp_debug` passes; on failure the message names the last kernel launched."""
    if request.config.getoption("--warp-debug"):
        pytest.skip("this session is the bounds-checked run already")
    log = tmp_path / "launches.txt"
    env = dict(os.environ, LODPRT_WARP_DEBUG_LOG=str(log))
    proc = subprocess.run([sys.executable, "-m", "pytest", "-q", "-x", "-p", "no:cacheprovider", "--warp-debug",
                           "-m", "warp_debug", str(TESTS)], capture_output=True, text=True, timeout=3600,
                          cwd=TESTS.parent, env=env)
    if proc.returncode != 0:
        launches = log.read_text().split() if log.is_file() else []
        last = launches[-1] if launches else "(none)"
        tail = "\n".join((proc.stdout + proc.stderr).splitlines()[-40:])
        pytest.fail(f"bounds-checked subset failed (exit {proc.returncode}); last kernel launched: {last}\n{tail}")
    assert " passed" in proc.stdout
    assert len(set(log.read_text().split())) >= 8  # the kernels ran (names logged once per launch)
