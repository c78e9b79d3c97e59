"""What a newcomer meets first (issue 26): ``lodprt --version``, ``python -m lodprt``, no CUDA driver note on a CPU
machine, the light box in ``info``, and the defaults the API shares with the command line."""

import json
import subprocess
import sys
from pathlib import Path

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



def test_set_camera_by_keyword_and_default_target(ball_store):
    """``Runtime.set_camera(eye=..., target=...)`` works by keyword, and without a target it looks at the scene's
    centre (the bounding box centre of the vertices the faces use, computed here independently), as the CLI."""
    import lodprt
    from lodprt.runtime.camera import Camera

    store = lodprt.open_store(ball_store[0])
    rt = lodprt.Runtime(store, device="cpu")
    cam = rt.set_camera(eye=(0.0, 0.6, 1.5), target=(0.0, 0.2, 0.0), width=64, height=48)
    assert cam.eye == (0.0, 0.6, 1.5) and cam.target == (0.0, 0.2, 0.0) and (cam.width, cam.height) == (64, 48)
    used = np.asarray(store.positions)[np.unique(np.asarray(store.faces))]
    centre = tuple(float(x) for x in (used.min(0) + used.max(0)) / 2)
    assert rt.set_camera(eye=(0.0, 0.6, 1.5)).target == pytest.approx(centre)
    assert rt.set_camera((0.0, 0.6, 1.5)).target == pytest.approx(centre)
    assert rt.update().stats["triangles"] > 0
    with pytest.raises(lodprt.LodprtError, match="eye given twice"):
        rt.set_camera((0, 0, 1), eye=(0, 0, 1))
    with pytest.raises(lodprt.LodprtError, match="give the eye"):
        rt.set_camera(target=(0, 0, 0))
    with pytest.raises(lodprt.LodprtError, match="not both"):
        rt.set_camera(Camera(eye=(0, 0, 1), target=(0, 0, 0)), eye=(0, 0, 2))


def test_short_reprs(ball, ball_store):
    """Store, Scene, BakeResult and Frame print one short line each, never an array."""
    import lodprt

    store = lodprt.open_store(ball_store[0])
    scene = lodprt.load_scene(ball)
    rt = lodprt.Runtime(store, device="cpu")
    rt.set_camera(eye=(0.0, 0.6, 1.5))
    frame = rt.update()
    result = lodprt.bake(scene, None, sh_order=2, device="cpu")
    for obj, words in ((store, f"{store.num_vertices:,} vertices"), (scene, f"{scene.num_vertices:,} vertices"),
                       (result, "4 samples"), (frame, f"{len(frame.triangles):,} triangles")):
        text = repr(obj)
        assert words in text and "\n" not in text and "array" not in text and len(text) < 200, text


def test_overwrite_errors_name_the_argument_or_the_flag(ball, ball_store, tmp_path):
    """An existing output: the library says ``overwrite=True``, the command line ``--overwrite``."""
    import lodprt

    with pytest.raises(lodprt.StoreError, match=r"pass overwrite=True to replace it"):
        lodprt.bake(lodprt.load_scene(ball), ball_store[0], sh_order=2, device="cpu")
    r = run_cli("bake", ball, "-o", ball_store[0], "--sh-order", "2")
    assert r.returncode == 2 and "pass --overwrite to replace it" in r.stderr and "overwrite=True" not in r.stderr


def cli(argv, capsys):
    """``lodprt ARGV`` in this process: (exit code, stdout, stderr)."""
    from lodprt.cli.main import main

    rc = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return rc, out, err


def refuse_work(monkeypatch):
    """Make reading a store fail loudly: a command refused before any work never gets there."""
    import lodprt.store.bake_store as bake_store

    def no_work(*args, **kwargs):
        raise AssertionError("the store was read before the output path was checked")

    monkeypatch.setattr(bake_store, "open_store", no_work)


EYE = ("--eye", 0, 1, 2)


@pytest.mark.parametrize("argv", [("radiance", "--sample", 0, *EYE, "-o", "{out}.npy"),
                                  ("diff", "--sample", 0, *EYE, "--size", 32, 24, "-o", "{out}.png")])
def test_output_in_a_missing_folder_is_refused_before_any_work(ball_store, tmp_path, monkeypatch, capsys, argv):
    """radiance and diff check OUT's folder first (diff's full-resolution re-bake, radiance's np.save traceback):
    one line, exit 2, the wording of the other commands, nothing read."""
    refuse_work(monkeypatch)
    out = tmp_path / "nope" / "x"
    rc, _, err = cli([argv[0], ball_store[0], *(str(a).format(out=out) for a in argv[1:])], capsys)
    assert rc == 2 and err.count("\n") == 1, err
    assert f"the folder {tmp_path / 'nope'} does not exist" in err and not (tmp_path / "nope").exists()


@pytest.mark.parametrize("argv", [("radiance", "--sample", 0, *EYE, "-o", "{out}.npy"),
                                  ("radiance", "--sample", 0, *EYE, "-o", "{out}.NPY"),
                                  ("diff", "--sample", 0, *EYE, "--size", 32, 24, "-o", "{out}.png")])
def test_output_that_is_a_folder_is_refused_even_with_overwrite(ball_store, tmp_path, monkeypatch, capsys, argv):
    """An OUT that is a folder is never replaced by the file (it was an IsADirectoryError traceback): one line
    naming it, exit 2, before any work, the folder kept."""
    refuse_work(monkeypatch)
    argv = [str(a).format(out=tmp_path / "x") for a in argv]
    folder = Path(argv[-1])
    (folder / "keep").mkdir(parents=True)
    rc, _, err = cli([argv[0], ball_store[0], *argv[1:], "--overwrite"], capsys)
    assert rc == 2 and err.count("\n") == 1 and f"{folder}: is a folder; the output must be a file" in err, err
    assert (folder / "keep").is_dir()


def test_radiance_takes_an_upper_case_suffix(ball_store, tmp_path, capsys):
    """-o R.NPY is a .npy (as render and export take .PNG, .GLB): written under that very name."""
    out = tmp_path / "R.NPY"
    rc, stdout, err = cli(["radiance", ball_store[0], "--sample", 0, *EYE, "-o", out], capsys)
    assert rc == 0, err
    assert [p.name for p in tmp_path.iterdir()] == ["R.NPY"] and f"wrote {out}" in stdout
    from lodprt.store.bake_store import open_store

    np.testing.assert_array_equal(np.load(out), open_store(ball_store[0]).radiance(0, (0, 1, 2)))


def test_compress_reports_the_input_as_stored_and_a_growth_as_larger(ball_store, tmp_path, capsys):
    """compress from a q8 store: 'was' is the q8 store's bytes per sample (not its float32 size), and re-encoding
    it larger (codec none) says 'larger', not '0.4x smaller'."""
    from lodprt.store.bake_store import open_store

    q8, back = tmp_path / "q8.zarr", tmp_path / "back.zarr"
    assert cli(["compress", ball_store[0], "-o", q8, "--codec", "q8"], capsys)[0] == 0
    info, raw = open_store(q8).info(), open_store(ball_store[0]).info()
    n = len(info["samples"])
    stored, float32 = (info["bytes_total"] + info["codec_bytes"]) / n / 1024, raw["bytes_total"] / n / 1024
    assert stored < float32 / 1.5
    rc, _, err = cli(["compress", q8, "-o", back, "--codec", "none"], capsys)
    assert rc == 0, err
    assert f"{float32:,.1f} KiB per sample (was {stored:,.1f} KiB, {float32 / stored:.1f}x larger;" in err, err
    rc, _, err = cli(["compress", q8, "-o", tmp_path / "again.zarr", "--codec", "q8"], capsys)
    assert rc == 0 and f"(was {stored:,.1f} KiB, the same size;" in err, err


@pytest.mark.parametrize("command, suffix", [("render", ".png"), ("render", ".npy"), ("compare", ".png"),
                                             ("export", ".glb")])
def test_drawn_output_that_is_a_folder_is_refused(ball_store, tmp_path, capsys, command, suffix, gl):
    """render, compare and export refuse an OUT that is a folder as the other commands do (their check,
    ``pictures.check_output``, let it through to an IsADirectoryError traceback): one line, exit 2, folder kept."""
    from lodprt.store.bake_store import open_store

    light = open_store(ball_store[0]).light_positions[0]
    folder = tmp_path / f"x{suffix}"
    (folder / "keep").mkdir(parents=True)
    rc, _, err = cli([command, ball_store[0], "--light", *light, *EYE, "-o", folder, "--overwrite"], capsys)
    assert rc == 2 and err.count("\n") == 1 and f"{folder}: is a folder; the output must be a file" in err, err
    assert (folder / "keep").is_dir()


def test_bake_refuses_light_cut_options_without_the_hierarchy(tmp_path, capsys):
    """`bake --no-hierarchy --threshold-deg 30` and `--no-hierarchy --hierarchy rounds` (and `--full
    --threshold-deg 30`) were accepted and ignored (exit 0): refused in one line naming both options, as
    `--threshold-deg -1` is, before the scene is read; the options at their defaults, not given, still pass."""
    from lodprt.cli.main import main

    out = tmp_path / "x.zarr"
    for opts, msg in ((["--no-hierarchy", "--threshold-deg", "30"],
                       "error: --threshold-deg 30 and --no-hierarchy: the light cut needs the hierarchy"),
                      (["--full", "--threshold-deg", "30"], "error: --threshold-deg 30 and --full: the light cut"),
                      (["--no-hierarchy", "--hierarchy", "rounds"],
                       "error: --hierarchy rounds and --no-hierarchy: --no-hierarchy builds no hierarchy"),
                      (["--threshold-deg", "-1"], "error: --threshold-deg -1.0: the light cut needs the hierarchy")):
        assert main(["bake", str(tmp_path / "missing.toml"), "-o", str(out), *opts]) == 2, opts
        err = capsys.readouterr().err
        assert msg in err and "missing.toml" not in err, (opts, err)
    assert main(["bake", str(tmp_path / "missing.toml"), "-o", str(out), "--no-hierarchy", "--full"]) == 2
    assert "missing.toml" in capsys.readouterr().err  # no option refused: the scene is read (and missing)
