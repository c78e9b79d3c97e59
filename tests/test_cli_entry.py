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


def lodprt(*args, module="lodprt"):
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
    run = lodprt("bake", ball, "-o", out, "--sh-order", "3", "--device", "cpu")
    assert run.returncode == 0, run.stderr
    return out, run


def test_version_and_python_m():
    """``lodprt --version`` and ``python -m lodprt --version`` print the package version; ``python -m lodprt``
    is the same parser (its --help lists the commands)."""
    for module in ("lodprt", "lodprt.cli.main"):
        r = lodprt("--version", module=module)
        assert r.returncode == 0 and r.stdout.strip() == f"lodprt {__version__}", (module, r.stdout, r.stderr)
    r = lodprt("--help")
    assert r.returncode == 0 and "turntable" in r.stdout and "usage: lodprt" in r.stdout
    r = lodprt("no-such-command")
    assert r.returncode == 2 and "invalid choice" in r.stderr


@pytest.mark.skipif(not CPU_ONLY, reason="the CUDA driver note is printed only where there is no CUDA driver")
def test_quiet_on_a_cpu_machine(ball, ball_store, tmp_path):
    """A bake and a radiance run (both start Warp) and info print no CUDA line on a machine without a GPU; ``-v``
    shows Warp's note, and ``--device cuda`` names it in its one-line error."""
    out, bake_run = ball_store
    assert "CUDA" not in bake_run.stderr + bake_run.stdout
    info = lodprt("info", out)
    assert info.returncode == 0 and "CUDA" not in info.stderr + info.stdout
    rad = lodprt("radiance", out, "--light", "0", "0.9", "0", "--eye", "0", "0.5", "1.5", "-o", tmp_path / "r.npy")
    assert rad.returncode == 0, rad.stderr
    assert "CUDA" not in rad.stderr + rad.stdout
    loud = lodprt("-v", "radiance", out, "--light", "0", "0.9", "0", "--eye", "0", "0.5", "1.5", "-o",
                  tmp_path / "v.npy")
    assert loud.returncode == 0 and "CUDA driver" in loud.stderr, loud.stderr
    cuda = lodprt("bake", ball, "-o", tmp_path / "c.zarr", "--device", "cuda")
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
