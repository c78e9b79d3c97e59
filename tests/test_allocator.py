"""One malloc arena for the ``lodprt`` command (``lodprt.allocator``): threads that allocate at once share one arena
after ``one_malloc_arena()`` and get arenas of their own without it (glibc's ``malloc_stats`` counts them), a
``MALLOC_ARENA_MAX`` the user set stands, the command line makes the call before it parses its arguments, and off
Linux nothing is called."""

import os
import platform
import re
import subprocess
import sys

import pytest

glibc = pytest.mark.skipif(platform.libc_ver()[0] != "glibc", reason="mallopt and malloc_stats are glibc's")

#: four threads allocate at the same time (a barrier holds each until all have allocated), then glibc prints its
#: arenas on stderr; stdout: what one_malloc_arena returned and the environment variable after it
THREADS = """
import ctypes, os, sys, threading
from lodprt.allocator import one_malloc_arena
made = one_malloc_arena() if sys.argv[1] == "call" else None
barrier = threading.Barrier(4)
held = []
def work():
    held.append([bytearray(65536) for _ in range(16)])  # below the mmap threshold: from the thread's arena
    barrier.wait()
threads = [threading.Thread(target=work) for _ in range(4)]
for t in threads: t.start()
for t in threads: t.join()
sys.stderr.flush()
ctypes.CDLL(None).malloc_stats()
print(made, os.environ.get("MALLOC_ARENA_MAX"))
"""


def run_child(code: str, *args, env_arena: str | None = None):
    env = {k: v for k, v in os.environ.items() if k != "MALLOC_ARENA_MAX"}
    if env_arena is not None:
        env["MALLOC_ARENA_MAX"] = env_arena
    out = subprocess.run([sys.executable, "-c", code, *args], capture_output=True, text=True, env=env)
    assert out.returncode == 0, out.stderr
    return out.stdout.strip(), len(re.findall(r"^Arena \d+:", out.stderr, re.MULTILINE))


@glibc
def test_threads_share_one_arena_after_the_call():
    said, arenas = run_child(THREADS, "call")
    assert said == "True 1"
    assert arenas == 1


@glibc
def test_threads_get_arenas_of_their_own_without_it():
    """The control: the same threads without the call make arenas of their own (what the call prevents)."""
    said, arenas = run_child(THREADS, "skip")
    assert said == "None None"
    assert arenas >= 3


@glibc
def test_the_users_setting_stands():
    said, arenas = run_child(THREADS, "call", env_arena="3")
    assert said == "False 3"
    assert 1 < arenas <= 3  # glibc read the user's limit at start-up


@glibc
def test_the_command_line_calls_it_before_parsing():
    """``lodprt --version`` exits while parsing: the arena is set by then, and child processes inherit it."""
    code = ("import os\nfrom lodprt.cli.main import main\ntry:\n    main(['--version'])\nexcept SystemExit:\n"
            "    pass\nprint(os.environ.get('MALLOC_ARENA_MAX'))")
    said, _ = run_child(code)
    assert said.splitlines()[-1] == "1"


def test_off_linux_nothing_changes(monkeypatch):
    """On Windows ``ctypes.CDLL(None)`` is a TypeError and macOS has no ``mallopt``: the call is a no-op there."""
    import ctypes

    from lodprt import allocator

    def no_library(*args, **kwargs):
        raise AssertionError("the C library was opened off Linux")

    monkeypatch.delenv("MALLOC_ARENA_MAX", raising=False)
    monkeypatch.setattr(ctypes, "CDLL", no_library)
    for name in ("win32", "darwin"):
        monkeypatch.setattr(allocator.sys, "platform", name)
        assert allocator.one_malloc_arena() is False
        assert "MALLOC_ARENA_MAX" not in os.environ
