"""The bounds-checked kernel subset: every test marked ``warp_debug`` (every kernel at least once, on every store
kind) run again in a subprocess with Warp's debug mode, where an index past an array's end stops the process. The
subprocess runs beside the rest of the suite from the end of collection (``debug_subset``)."""

import importlib
import pkgutil

import pytest

import debug_subset


def defined_kernels() -> set[str]:
    """The names of every ``@wp.kernel`` the package defines (each module of ``lodprt.kernels``, its own kernels)."""
    import warp as wp

    import lodprt.kernels as package

    names = set()
    for info in pkgutil.iter_modules(package.__path__):
        module = importlib.import_module(f"{package.__name__}.{info.name}")
        names |= {v.key for v in vars(module).values()
                  if isinstance(v, wp.Kernel) and getattr(v.module, "name", None) == module.__name__}
    return names


def test_marked_subset_passes_bounds_checked(request):
    """`pytest --warp-debug -m warp_debug` passes; on failure the message names the last kernel launched. The
    session started it in the background when collection ended (``debug_subset``, ``tests/conftest.py``)."""
    if request.config.getoption("--warp-debug"):
        pytest.skip("this session is the bounds-checked run already")
    code, out, launches = request.config.stash[debug_subset.KEY].result()
    if code != 0:
        last = launches[-1] if launches else "(none)"
        tail = "\n".join(out.splitlines()[-40:])
        pytest.fail(f"bounds-checked subset failed (exit {code}); last kernel launched: {last}\n{tail}")
    assert " passed" in out
    missing = defined_kernels() - set(launches)  # every kernel runs at least once bounds-checked
    assert not missing, f"kernels no warp_debug test launches: {sorted(missing)}"
