"""What a newcomer meets first (issue 26): ``lodprt --version``, ``python -m lodprt``, no CUDA driver note on a CPU
machine, the light box in ``info``, and the defaults the API shares with the command line."""

import json
import subprocess
import sys

import numpy as np
import pytest

from lodprt.devices import available_devices
from lodprt.version import __version__

CPU_ONLY = not any(d.startswith("cuda") for d in available_devices())


def run_cli(*args, module="lodprt"):
    return subprocess.run([sys.executable, "-m", module, *map(str, args)], capture_output=True, text=True)


@pytest.fixture(scope="module")
def ball(tmp_path_factory):
    """A small scene file: an icosphere (642 vertices) on a 24 x 24 floor, 2 x 1 x 2 lights."""
    import trimesh

    folder = tmp_path_factory.mktemp("ball")
    mesh = trimesh.creation.icosphere(subdivisions=3, radius=0.3)
    mesh.apply_translation((0.0, 0.3, 0.0))
    mesh.export(folder / "ball.obj")
    scene = folder / "ball.toml"
    scene.write_text('[[object]]\nmesh = "ball.obj"\n[floor]\nresolution = 24\n[lights]\ngrid = [2, 1, 2]\n')
    return scene


@pytest.fixture(scope="module")
def ball_store(ball, tmp_path_factory):
    """``lodprt bake`` of ``ball`` with the command line's defaults (SH order 3): the store's path and the run."""
    out = tmp_path_factory.mktemp("ball-store") / "ball.zarr"
    run = run_cli("bake", ball, "-o", out, "--sh-order", "3", "--device", "cpu")
    assert run.returncode == 0, run.stderr
    return out, run


def test_version_and_python_m():
    """``lodprt --version`` and ``python -m lodprt --version`` print the package version; ``python -m lodprt``
    is the same parser (its --help lists the commands)."""
    for module in ("lodprt", "lodprt.cli.main"):
        r = run_cli("--version", module=module)
        assert r.returncode == 0 and r.stdout.strip() == f"lodprt {__version__}", (module, r.stdout, r.stderr)
    r = run_cli("--help")
    assert r.returncode == 0 and "turntable" in r.stdout and "usage: lodprt" in r.stdout
    r = run_cli("no-such-command")
    assert r.returncode == 2 and "invalid choice" in r.stderr


@pytest.mark.skipif(not CPU_ONLY, reason="the CUDA driver note is printed only where there is no CUDA driver")
def test_quiet_on_a_cpu_machine(ball, ball_store, tmp_path):
    """A bake and a radiance run (both start Warp) and info print no CUDA line on a machine without a GPU; ``-v``
    shows Warp's note, and ``--device cuda`` names it in its one-line error."""
    out, bake_run = ball_store
    assert "CUDA" not in bake_run.stderr + bake_run.stdout
    info = run_cli("info", out)
    assert info.returncode == 0 and "CUDA" not in info.stderr + info.stdout
    rad = run_cli("radiance", out, "--light", "0", "0.9", "0", "--eye", "0", "0.5", "1.5", "-o", tmp_path / "r.npy")
    assert rad.returncode == 0, rad.stderr
    assert "CUDA" not in rad.stderr + rad.stdout
    loud = run_cli("-v", "radiance", out, "--light", "0", "0.9", "0", "--eye", "0", "0.5", "1.5", "-o",
                  tmp_path / "v.npy")
    assert loud.returncode == 0 and "CUDA driver" in loud.stderr, loud.stderr
    cuda = run_cli("bake", ball, "-o", tmp_path / "c.zarr", "--device", "cuda")
    assert cuda.returncode == 2 and len(cuda.stderr.strip().splitlines()) == 1, cuda.stderr
    assert "'cuda' is not available" in cuda.stderr and "CUDA driver" in cuda.stderr


def test_device_cuda_names_warps_note():
    """``resolve_device("cuda")`` on a machine without one says which devices there are and, where Warp said why,
    its note."""
    from lodprt.devices import CUDA_NOTES, resolve_device
    from lodprt.errors import LodprtError

    if not CPU_ONLY:
        assert resolve_device("cuda") == "cuda:0"
        return
    with pytest.raises(LodprtError, match="available: cpu") as err:
        resolve_device("cuda")
    assert all(note in str(err.value) for note in CUDA_NOTES)


def test_api_bake_defaults_are_the_cli_defaults(ball, ball_store, tmp_path):
    """``lodprt.bake(scene, out)`` writes the same kind of store as ``lodprt bake``: a 5-degree light cut with the
    hierarchy (the same kept vertices per sample); ``full=True`` is ``--full`` and ``hierarchy=False`` is
    ``--no-hierarchy`` (both full resolution)."""
    import lodprt

    cli_store = lodprt.open_store(ball_store[0])
    api = tmp_path / "api.zarr"
    lodprt.bake(lodprt.load_scene(ball), api, sh_order=3, device="cpu")
    api_store = lodprt.open_store(api)
    keys = ("mode", "threshold_deg", "with_hierarchy", "sh_order")
    assert {k: api_store.attrs[k] for k in keys} == {k: cli_store.attrs[k] for k in keys}
    assert api_store.attrs["mode"] == "cut" and api_store.attrs["threshold_deg"] == 5.0
    assert [s["vertices_kept"] for s in api_store.info()["samples"]] == \
        [s["vertices_kept"] for s in cli_store.info()["samples"]]
    assert all(s["vertices_kept"] < api_store.num_vertices for s in api_store.info()["samples"])
    runs = {"full": (["--full"], {"full": True}), "none": (["--no-hierarchy"], {"hierarchy": False})}
    for name, (flags, kw) in runs.items():
        r = run_cli("bake", ball, "-o", tmp_path / f"cli-{name}.zarr", "--sh-order", "2", "--device", "cpu", *flags)
        assert r.returncode == 0, r.stderr
        lodprt.bake(lodprt.load_scene(ball), tmp_path / f"api-{name}.zarr", sh_order=2, device="cpu", **kw)
        a, c = (lodprt.open_store(tmp_path / f"{w}-{name}.zarr").attrs for w in ("api", "cli"))
        assert (a["mode"], a["threshold_deg"], a["with_hierarchy"]) == (c["mode"], c["threshold_deg"],
                                                                          c["with_hierarchy"]) and a["mode"] == "full"
    with pytest.raises(lodprt.LodprtError, match="needs the hierarchy"):
        lodprt.bake(lodprt.load_scene(ball), tmp_path / "x.zarr", device="cpu", hierarchy=False, threshold_deg=10.0)

