"""CI's rule on skipped tests: a test may skip only because this machine has no GPU (CUDA), no offscreen OpenGL
context or no X server. Any other skip -- a missing mesh, a missing dependency, a fixture that gave up -- would let
a broken set-up pass as green, so under CI (the ``CI`` environment variable set, as ``.ci/run`` does) it fails the
session: the summary names each such test with its reason and the exit status is 1.

``tests/conftest.py`` registers it (``register``); ``tests/test_skip_policy.py`` runs it on tiny test files.
"""

from __future__ import annotations

import os

import pytest

#: Lower-case pieces of the skip reasons allowed under CI: what the machine lacks, never what the project lacks.
ALLOWED = (
    "no offscreen opengl context",  # the gl fixture (tests/conftest.py)
    "xvfb",  # tests/test_viewer.py: no virtual X server to open the viewer's window on
    "x display",
    "x server",
    "cuda",
    "gpu",
    "this session is the bounds-checked run already",  # tests/test_warp_debug.py inside its own --warp-debug run
)

#: Values of ``CI`` that mean "not CI".
OFF = ("", "0", "false", "no", "off")


def ci_enabled(environ=os.environ) -> bool:
    """True when the ``CI`` environment variable says this is a CI run."""
    return environ.get("CI", "").strip().lower() not in OFF


def allowed(reason: str) -> bool:
    """Whether a skip for ``reason`` is one CI accepts (``ALLOWED``)."""
    text = reason.lower()
    return any(piece in text for piece in ALLOWED)


def skip_reason(report) -> str | None:
    """The reason of a skipped test or collector report; None for anything else (xfail included)."""
    if not report.skipped or hasattr(report, "wasxfail"):
        return None
    longrepr = report.longrepr
    reason = longrepr[2] if isinstance(longrepr, tuple) and len(longrepr) == 3 else str(longrepr)
    return str(reason).removeprefix("Skipped: ")


class SkipPolicy:
    """The pytest plugin: records the skips that are not allowed and fails the session on them."""

    def __init__(self):
        self.bad: list[tuple[str, str]] = []

    def note(self, report) -> None:
        reason = skip_reason(report)
        if reason is not None and not allowed(reason):
            self.bad.append((report.nodeid or str(report.fspath), reason))

    def pytest_runtest_logreport(self, report):
        self.note(report)

    def pytest_collectreport(self, report):
        self.note(report)

    def pytest_sessionfinish(self, session, exitstatus):
        if self.bad and exitstatus in (pytest.ExitCode.OK, pytest.ExitCode.NO_TESTS_COLLECTED):
            session.exitstatus = pytest.ExitCode.TESTS_FAILED

    def pytest_terminal_summary(self, terminalreporter):
        if not self.bad:
            return
        terminalreporter.section("skips CI does not allow", sep="=", red=True)
        for nodeid, reason in self.bad:
            terminalreporter.line(f"{nodeid}: {reason}")
        terminalreporter.line(f"{len(self.bad)} skipped for a reason other than a missing GPU, OpenGL context or X "
                              "server (tests/skip_policy.py); the session fails")


def register(config, *, enabled: bool | None = None) -> None:
    """Register the policy on ``config`` when ``enabled`` (default: ``ci_enabled()``)."""
    if ci_enabled() if enabled is None else enabled:
        config.pluginmanager.register(SkipPolicy(), "lodprt-skip-policy")
