"""Shared fixtures: every available Warp device, the test meshes shipped in tests/data, an OpenGL context check."""

import functools
import sys
from pathlib import Path

import pytest

import debug_subset
import skip_policy
from lodprt.devices import available_devices

REPO = Path(__file__).resolve().parents[1]
#: The test meshes (stanford-bunny, spot, fandisk) as xz-compressed OBJ files, read by lodprt's own mesh loader
#: (tests/data/README.md: where each comes from, its licence).
DATA = Path(__file__).resolve().parent / "data"
BUNNY = DATA / "stanford-bunny.obj.xz"
SPOT = DATA / "spot.obj.xz"
FANDISK = DATA / "fandisk.obj.xz"


@pytest.fixture(params=available_devices())
def device(request):
    """Each available Warp device in turn ("cpu", then every "cuda:N")."""
    return request.param


@pytest.fixture(scope="session")
def bunny_path():
    """The Stanford bunny shipped in tests/data (35,947 vertices, 34,834 referenced)."""
    return BUNNY


@pytest.fixture(scope="session")
def bunny_floor(bunny_path, request):
    """The bunny on a 40 x 40 floor, default 3 x 1 x 3 lights (37,547 vertices). Bounds-checked (``--warp-debug``),
    the bunny decimated by pymeshlab to a quarter of its faces, as the view-cut benchmark's ``bunny-coarse`` scene
    (``benchmarks/procedural.py``: 10,377 vertices with the floor, more than ``lodprt.launches.SPLIT_MIN``, so the
    per-vertex passes still run in slices): there every array access is checked whatever the arrays' sizes, so the
    size that makes an optimised run's stray index land outside the allocation buys nothing, and the debug build's
    unoptimised kernels take most of the subset's time."""
    from lodprt.model.scene import THESIS_MATERIAL, assemble_scene, load_mesh

    if request.config.getoption("--warp-debug"):
        if str(REPO / "benchmarks") not in sys.path:
            sys.path.insert(0, str(REPO / "benchmarks"))
        from procedural import decimated_bunny

        pos, faces = decimated_bunny(None)
    else:
        pos, faces = load_mesh(bunny_path)
    return assemble_scene([("bunny", pos, faces, THESIS_MATERIAL)], (40, 1.0, THESIS_MATERIAL), {}, "lights", "bunny")


@pytest.fixture(scope="session")
def bunny_hierarchy(bunny_floor):
    """The vertex hierarchy of ``bunny_floor`` (built once per test session)."""
    from lodprt.model.hierarchy_build import build_hierarchy

    return build_hierarchy(bunny_floor.positions, bunny_floor.faces, bunny_floor.normals)


@pytest.fixture(scope="session")
def bunny_bake(bunny_floor, bunny_hierarchy, tmp_path_factory):
    """A light-cut bake (30 degrees, SH order 4, 3 x 1 x 3 lights) of ``bunny_floor``: the store's path."""
    from lodprt.precompute.bake import bake

    path = tmp_path_factory.mktemp("bunny-bake") / "bunny.zarr"
    bake(bunny_floor, path, sh_order=4, device="cpu", threshold_deg=30.0, tree=bunny_hierarchy)
    return path


@functools.cache
def gl_unavailable() -> str | None:
    """Why no offscreen OpenGL 3.3 context can be made here (None when one can)."""
    from lodprt.errors import LodprtError
    from lodprt.display.render import create_context

    try:
        create_context().release()
    except LodprtError as exc:
        return str(exc)
    return None


@pytest.fixture
def gl():
    """Skips (saying so) only when no OpenGL context can be made; any other error in a GL test fails it."""
    why = gl_unavailable()
    if why:
        pytest.skip(f"no offscreen OpenGL context on this machine: {why}")


def pytest_addoption(parser):
    parser.addoption("--warp-debug", action="store_true", default=False,
                     help="compile Warp kernels in debug mode (bounds-checked array access; an index past an "
                          "array's end stops the process, and the last kernel launched is printed on stderr)")


def pytest_configure(config):
    skip_policy.register(config)  # under CI, a skip for anything but a missing GPU, GL context or X server fails
    config.addinivalue_line("markers", "warp_debug: the focused subset that runs every kernel on every store kind; "
                            "`python -m pytest --warp-debug -m warp_debug` runs it bounds-checked")
    if config.getoption("--warp-debug"):
        import os

        import warp as wp

        import threading

        wp.config.mode = "debug"  # before any module is loaded: debug builds hash (and cache) apart
        launch = wp.launch
        lock = threading.Lock()  # debug-mode CPU launches from several threads at once crash Warp 1.19 itself

        log_path = os.environ.get("LODPRT_WARP_DEBUG_LOG")

        def named_launch(kernel, *args, **kw):  # a failed bounds check aborts: the log names the last kernel
            with lock:
                if log_path:
                    with open(log_path, "a") as f:
                        f.write(f"{getattr(kernel, 'key', kernel)}\n")
                return launch(kernel, *args, **kw)

        wp.launch = named_launch


def pytest_collection_finish(session):
    """The bounds-checked subset starts now, beside the rest of the suite, when this session runs its test
    (``debug_subset``)."""
    debug_subset.start(session)


def pytest_sessionfinish(session):
    debug_subset.finish(session)
