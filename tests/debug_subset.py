"""The bounds-checked kernel subset of ``tests/test_warp_debug.py`` as a background process.

``pytest --warp-debug -m warp_debug`` serialises its kernel launches (``tests/conftest.py``: Warp 1.19's debug-mode
CPU kernels crash when launched from several threads at once), so it keeps one core busy for most of the suite's
time. ``tests/conftest.py`` starts it (``Subset``) as soon as collection shows that the session will run
``TEST_ID``, so that it runs beside the rest of the suite instead of after it; the test waits for its result, and
the session's end stops it if it is still running (an interrupted or failed-early session).
"""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
import tempfile
from pathlib import Path

import pytest

TESTS = Path(__file__).resolve().parent
#: the test that reads the subset's result
TEST_ID = "test_warp_debug.py::test_marked_subset_passes_bounds_checked"
#: seconds the test waits for the subset
TIMEOUT = 3600


class Subset:
    """``python -m pytest -q -x --warp-debug -m warp_debug tests`` started now, its output and the names of the
    kernels it launched (``LODPRT_WARP_DEBUG_LOG``) in a temporary folder of its own."""

    def __init__(self):
        self.folder = Path(tempfile.mkdtemp(prefix="lodprt-warp-debug-"))
        self.log = self.folder / "launches.txt"
        self.out = open(self.folder / "output.txt", "w+")
        env = dict(os.environ, LODPRT_WARP_DEBUG_LOG=str(self.log))
        self.proc = subprocess.Popen([sys.executable, "-m", "pytest", "-q", "-x", "-p", "no:cacheprovider",
                                      "--warp-debug", "-m", "warp_debug", str(TESTS)],
                                     stdout=self.out, stderr=subprocess.STDOUT, text=True, cwd=TESTS.parent, env=env,
                                     start_new_session=True)  # its own process group: stop() ends its children too

    def result(self) -> tuple[int, str, list[str]]:
        """(exit status, output, kernel names launched in order) once the subset has finished (at most TIMEOUT
        seconds from now; subprocess.TimeoutExpired after)."""
        code = self.proc.wait(timeout=TIMEOUT)
        self.out.seek(0)
        launches = self.log.read_text().split() if self.log.is_file() else []
        return code, self.out.read(), launches

    def stop(self) -> None:
        """Kill the subset (its process group) if it still runs, and remove its folder."""
        if self.proc.poll() is None:
            os.killpg(self.proc.pid, signal.SIGKILL)
        self.proc.wait()
        self.out.close()
        shutil.rmtree(self.folder, ignore_errors=True)


KEY = pytest.StashKey[Subset]()


def wanted(session: pytest.Session) -> bool:
    """Whether this session will run the test that reads the subset (not inside the subset's own --warp-debug
    run, and not when it only collects)."""
    config = session.config
    if config.getoption("--warp-debug") or config.option.collectonly:
        return False
    return any(item.nodeid.endswith(TEST_ID) for item in session.items)


def start(session: pytest.Session) -> None:
    """Start the subset in the background when this session will ask for it (``wanted``)."""
    if wanted(session):
        session.config.stash[KEY] = Subset()


def finish(session: pytest.Session) -> None:
    """Stop the subset started for this session, if any."""
    sub = session.config.stash.get(KEY, None)
    if sub is not None:
        sub.stop()
        del session.config.stash[KEY]
