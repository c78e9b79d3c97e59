"""The CI skip policy (tests/skip_policy.py) on tiny test sessions run in a subprocess: a skip for a missing file
or module fails the session under CI, a skip for a missing OpenGL context, X server or GPU does not."""

import os
import subprocess
import sys
from pathlib import Path

import pytest

import skip_policy

TESTS = Path(__file__).resolve().parent
CONFTEST = "import skip_policy\n\n\ndef pytest_configure(config):\n    skip_policy.register(config)\n"


def session(tmp_path, body, ci="true"):
    """Run one test file ``body`` with the policy's conftest; (exit status, output)."""
    (tmp_path / "conftest.py").write_text(CONFTEST)
    (tmp_path / "test_tiny.py").write_text("import pytest\n\n" + body)
    env = {k: v for k, v in os.environ.items() if k != "CI"}
    env["PYTHONPATH"] = os.pathsep.join([str(TESTS), env.get("PYTHONPATH", "")])
    if ci is not None:
        env["CI"] = ci
    r = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "--rootdir", str(tmp_path),
                        "-c", os.devnull, str(tmp_path)], capture_output=True, text=True, env=env, cwd=tmp_path,
                       timeout=120)
    return r.returncode, r.stdout + r.stderr


def test_skip_for_a_missing_file_fails_under_ci(tmp_path):
    rc, out = session(tmp_path, 'def test_a():\n    pytest.skip("../shared/models/spot.obj is not present")\n\n\n'
                                "def test_b():\n    pass\n")
    assert rc == 1, out
    assert "skips CI does not allow" in out and "test_tiny.py::test_a: ../shared/models/spot.obj is not present" in out
    assert "1 passed, 1 skipped" in out


def test_module_level_importorskip_fails_under_ci(tmp_path):
    rc, out = session(tmp_path, 'pytest.importorskip("no_such_module_lodprt")\n\n\ndef test_a():\n    pass\n')
    assert rc == 1, out
    assert "test_tiny.py: could not import 'no_such_module_lodprt'" in out


def test_skips_for_missing_gl_x_server_or_gpu_pass_under_ci(tmp_path):
    body = "".join(f"def test_{k}():\n    pytest.skip({why!r})\n\n\n" for k, why in enumerate([
        "no offscreen OpenGL context on this machine: EGL: no display",
        "Xvfb is not installed (Debian: apt-get install xvfb); the viewer needs an X display",
        "Xvfb did not start", "no CUDA device"])) + "@pytest.mark.xfail(reason='known')\ndef test_x():\n    assert 0\n"
    rc, out = session(tmp_path, body)
    assert rc == 0, out
    assert "4 skipped, 1 xfailed" in out and "skips CI does not allow" not in out


def test_outside_ci_a_bad_skip_is_only_a_skip(tmp_path):
    for ci in (None, "false", "0"):
        rc, out = session(tmp_path, 'def test_a():\n    pytest.skip("data missing")\n', ci=ci)
        assert rc == 0 and "1 skipped" in out, (ci, out)


@pytest.mark.parametrize("value, on", [("true", True), ("1", True), ("yes", True), ("", False), ("false", False),
                                       ("False", False), ("0", False), (None, False)])
def test_ci_variable(value, on):
    assert skip_policy.ci_enabled({} if value is None else {"CI": value}) is on


def test_ci_pytest_fails_when_no_tests_run_and_sets_ci(tmp_path):
    """.ci/pytest (what .ci/run runs): exit status 5 (no tests collected) becomes 1; a bad skip fails under CI=true."""
    script = TESTS.parent / ".ci" / "pytest"
    env = {k: v for k, v in os.environ.items() if k != "CI"}
    env["PYTHONPATH"] = os.pathsep.join([str(TESTS), env.get("PYTHONPATH", "")])
    args = ["-p", "no:cacheprovider", "--rootdir", str(tmp_path), "-c", os.devnull, str(tmp_path)]
    (tmp_path / "conftest.py").write_text(CONFTEST)
    r = subprocess.run([str(script), *args], capture_output=True, text=True, env=env, cwd=tmp_path, timeout=120)
    assert r.returncode == 1 and "collected no tests" in r.stderr, r.stdout + r.stderr
    (tmp_path / "test_tiny.py").write_text('import pytest\n\n\ndef test_a():\n    pytest.skip("no data")\n')
    r = subprocess.run([str(script), *args], capture_output=True, text=True, env=env, cwd=tmp_path, timeout=120)
    assert r.returncode == 1 and "skips CI does not allow" in r.stdout, r.stdout + r.stderr
    (tmp_path / "test_tiny.py").write_text("def test_a():\n    pass\n")
    r = subprocess.run([str(script), *args], capture_output=True, text=True, env=env, cwd=tmp_path, timeout=120)
    assert r.returncode == 0 and "1 passed" in r.stdout, r.stdout + r.stderr
