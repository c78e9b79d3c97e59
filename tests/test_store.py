"""Bake store: exact round trip, zarr-only readability, no clobbering, and the CLI on top of it."""

import json
import subprocess
import sys

import numpy as np
import pytest

from lodprt.model import sh
from lodprt.precompute.bake import bake
from lodprt.devices import load_kernels
from lodprt.precompute.baker import Baker, bake_kernels
from lodprt.errors import StoreError
from lodprt.model.scene import THESIS_MATERIAL, assemble_scene, load_mesh
from lodprt.store.bake_store import open_store

LIGHTS = {"grid": [2, 1, 2]}


@pytest.fixture(scope="module")
def small(bunny_path):
    pos, faces = load_mesh(bunny_path)
    return assemble_scene([("bunny", pos, faces, THESIS_MATERIAL)], (30, 0.5, THESIS_MATERIAL), LIGHTS, "lights", "bunny")


@pytest.fixture(scope="module")
def baked(small, tmp_path_factory):
    path = tmp_path_factory.mktemp("store") / "b.zarr"
    res = bake(small, path, sh_order=3, device="cpu", full=True)  # with the hierarchy, every vertex
    return path, res


def test_round_trip_exact(small, baked):
    """What is read back equals, bit for bit, the scene arrays and what the kernels computed for each sample."""
    path, res = baked
    store = open_store(path)
    np.testing.assert_array_equal(store.positions, small.positions.astype(np.float32))
    np.testing.assert_array_equal(store.faces, small.faces)
    np.testing.assert_array_equal(store.light_positions, small.lights.positions.astype(np.float32))
    load_kernels("cpu", *bake_kernels())
    ids = np.flatnonzero(small.referenced).astype(np.int32)
    baker = Baker(small, 3, "cpu", ids)
    for k, light in enumerate(small.lights.positions):
        got_ids, got = store.sample(k)
        np.testing.assert_array_equal(got_ids, ids)
        np.testing.assert_array_equal(got, baker.sample(light)[0])
    assert store.sh_order == 3 and len(res.samples) == 4


def test_hierarchy_stored_and_reported(small, baked):
    """The bake stores the vertex hierarchy bit for bit and info reports its nodes, roots and build time."""
    from lodprt.model.hierarchy_build import build_hierarchy

    path, res = baked
    store = open_store(path)
    stored = store.hierarchy()
    fresh = build_hierarchy(small.positions, small.faces, small.normals)  # deterministic: same tree again
    for name, arr in fresh.to_arrays().items():
        np.testing.assert_array_equal(getattr(stored, name), arr)
    info = store.info()
    assert info["hierarchy_nodes"] == fresh.num_nodes and info["hierarchy_roots"] == len(fresh.roots)
    assert info["hierarchy_seconds"] > 0 and res.hierarchy_seconds == info["hierarchy_seconds"]


def test_readable_with_zarr_alone(baked):
    """docs/FORMAT.md's recipe: zarr + numpy reconstruct the same radiance as Store.radiance."""
    import zarr

    path, _ = baked
    root = zarr.open_group(str(path), mode="r")
    assert root.attrs["format"] == "lodprt" and root.attrs["format_version"] == 1
    pos = root["scene/positions"][...]
    ids = root["samples/00001/vertex_ids"][...]
    coeffs = root["samples/00001/coefficients"][...]
    eye = np.array([0.0, 0.3, 0.5])
    d = eye - pos[ids].astype(np.float64)
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    rad = np.einsum("kci,ki->kc", coeffs, sh.basis(d, root.attrs["sh_order"])) * np.array(root["lights"].attrs["intensity"])
    ref = open_store(path).radiance(1, eye)
    np.testing.assert_allclose(ref[ids], rad, rtol=1e-5, atol=1e-6)
    unref = np.setdiff1d(np.arange(len(pos)), ids)
    assert (ref[unref] == 0).all()


def test_never_clobbers(small, baked, tmp_path):
    """An existing store is kept without overwrite; a non-store folder is refused even with overwrite."""
    path, _ = baked
    before = open_store(path).read("samples/00000/coefficients").copy()
    with pytest.raises(StoreError, match="already exists"):
        bake(small, path, sh_order=2, device="cpu", hierarchy=False)
    np.testing.assert_array_equal(open_store(path).read("samples/00000/coefficients"), before)
    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "thesis.tex").write_text("precious")
    with pytest.raises(StoreError, match="not a lodprt store"):
        bake(small, mine, sh_order=2, device="cpu", overwrite=True, hierarchy=False)
    assert (mine / "thesis.tex").read_text() == "precious"
    assert not list(tmp_path.glob("*.partial-*"))


def test_overwrite_replaces_a_store(small, tmp_path):
    """With overwrite a store is replaced by the new bake, and no partial folder is left behind."""
    path = tmp_path / "o.zarr"
    bake(small, path, sh_order=2, device="cpu", hierarchy=False)
    bake(small, path, sh_order=3, device="cpu", overwrite=True, hierarchy=False)
    assert open_store(path).sh_order == 3
    assert sorted(p.name for p in tmp_path.iterdir()) == ["o.zarr"]


def test_a_symlinked_or_nameless_destination_is_refused(small, baked, tmp_path):
    """OUT a symbolic link to a store is refused, even with overwrite (replacing it emptied the store it pointed
    to); '.' and '..' are refused with a message (they raised from pathlib). The linked store is untouched, and a
    parked link is removed as a link, never what it points to."""
    from lodprt.store.writer import StoreWriter, clean_leftovers

    path, _ = baked
    before = sorted(p.relative_to(path) for p in path.rglob("*"))
    link = tmp_path / "link.zarr"
    link.symlink_to(path)
    with pytest.raises(StoreError, match=r"link\.zarr: is a symbolic link \(to .*b\.zarr\); name the store's own"):
        bake(small, link, sh_order=2, device="cpu", overwrite=True, hierarchy=False)
    assert link.is_symlink() and sorted(p.relative_to(path) for p in path.rglob("*")) == before
    for name in (".", ".."):
        with pytest.raises(StoreError, match=rf"name the store's folder \(e\.g\. out\.zarr\), not '\{name}'"):
            StoreWriter(name, overwrite=True)
    parked = tmp_path / "x.zarr.replaced-999999"  # a parked link (an older lodprt could leave one)
    parked.symlink_to(path)
    clean_leftovers(tmp_path / "x.zarr")
    assert sorted(p.relative_to(path) for p in path.rglob("*")) == before


def test_check_settings_names_the_scene_before_what_it_derives():
    """Another scene changes settings derived from it (ray_offset) too: the message names the scene's fingerprint,
    whatever the settings' order, not a setting the user never gave."""
    from lodprt.errors import LodprtError
    from lodprt.store.resume import check_settings

    recorded = {"ray_offset": 1e-4, "fingerprint": {"positions": "a", "faces": "f"}}
    wanted = {"ray_offset": 3e-4, "fingerprint": {"positions": "b", "faces": "f"}}
    with pytest.raises(LodprtError, match=r"the scene differs from the one it baked \(fingerprint of positions\)"):
        check_settings("s.zarr", recorded, wanted)


def test_bake_arguments_of_the_wrong_kind_are_refused(small):
    """jobs 0, -2, 1.5, sh_order '3' and threshold_deg '5' are refused naming the argument (jobs 0 ran with one
    thread, 1.5 raised from itertools, the strings TypeErrors)."""
    from lodprt.errors import LodprtError

    for kw, msg in (({"jobs": 0}, "jobs 0"), ({"jobs": -2}, "jobs -2"), ({"jobs": 1.5}, "jobs 1.5"),
                    ({"sh_order": "3"}, "sh_order '3'"), ({"threshold_deg": "5"}, "threshold_deg '5'")):
        with pytest.raises(LodprtError, match=msg):
            bake(small, None, **{"sh_order": 2, "device": "cpu", **kw})


def test_cli_names_the_options_it_refuses(tmp_path):
    """--sh-order 0 and --threshold-deg -1 are named as the options, before the scene is read."""
    r = lodprt("bake", tmp_path / "none.obj", "-o", tmp_path / "x.zarr", "--sh-order", "0")
    assert r.returncode == 2 and "--sh-order 0: a whole number from 1" in r.stderr, r.stderr
    r = lodprt("bake", tmp_path / "none.obj", "-o", tmp_path / "x.zarr", "--threshold-deg", "-1")
    assert r.returncode == 2 and "--threshold-deg -1.0: the light cut needs" in r.stderr, r.stderr


def test_open_errors(tmp_path):
    """Opening a missing path or a folder that is not a store names the path."""
    with pytest.raises(StoreError, match="no such store"):
        open_store(tmp_path / "missing.zarr")
    with pytest.raises(StoreError, match="not a lodprt store"):
        open_store(tmp_path)


def lodprt(*args, cwd=None):
    return subprocess.run([sys.executable, "-m", "lodprt.cli.main", *map(str, args)], capture_output=True, text=True, cwd=cwd)


def test_cli_bake_info_radiance(tmp_path, bunny_path):
    """lodprt bake / info --json / radiance work end to end on a TOML scene with the bunny (tests/data)."""
    scene = tmp_path / "scene.toml"
    scene.write_text(
        f'[[object]]\nmesh = "{bunny_path.as_posix()}"\n[floor]\nresolution = 20\n[lights]\ngrid = [2, 1, 1]\n'
    )
    out = tmp_path / "b.zarr"
    r = lodprt("bake", scene, "-o", out, "--sh-order", "3", "--device", "cpu", "--no-hierarchy")
    assert r.returncode == 0, r.stderr
    r = lodprt("info", out, "--json")
    assert r.returncode == 0, r.stderr
    info = json.loads(r.stdout)
    assert info["vertices"] == 35947 + 400 and info["sh_order"] == 3 and info["bake_seconds"] > 0
    assert [s["index"] for s in info["samples"]] == [0, 1]
    assert info["hierarchy_nodes"] is None
    assert all(s["vertices_kept"] == 34834 + 400 and s["bytes"] == s["vertices_kept"] * (4 + 9 * 4) for s in info["samples"])
    rad = tmp_path / "rad.npy"
    r = lodprt("radiance", out, "--sample", "1", "--eye", "0", "0.3", "0.6", "-o", rad)
    assert r.returncode == 0, r.stderr
    arr = np.load(rad)
    assert arr.shape == (info["vertices"], 3) and arr.dtype == np.float32 and np.isfinite(arr).all()
    np.testing.assert_array_equal(arr, open_store(out).radiance(1, (0, 0.3, 0.6)))
    # the second bake into the same path is refused with a clear one-line error
    r = lodprt("bake", scene, "-o", out)
    assert r.returncode == 2 and "already exists" in r.stderr and "Traceback" not in r.stderr


def test_cli_errors_are_one_line(tmp_path):
    """Bad scene, bad sample index and unknown device give exit code 2 and a message naming the culprit."""
    r = lodprt("bake", tmp_path / "none.obj", "-o", tmp_path / "x.zarr")
    assert r.returncode == 2 and "none.obj" in r.stderr and "Traceback" not in r.stderr
    r = lodprt("bake", "demo", "-o", tmp_path / "x.zarr", "--device", "tpu")
    assert r.returncode == 2 and "tpu" in r.stderr
    r = lodprt("info", tmp_path)
    assert r.returncode == 2 and "not a lodprt store" in r.stderr


def test_cli_cut_bake_and_diff_picture(tmp_path):
    """Default bake (light cut) on spot + floor, then lodprt diff writes a 3-panel PNG with its error numbers."""
    from conftest import SPOT as spot

    scene = tmp_path / "spot.toml"
    scene.write_text(f'[[object]]\nmesh = "{spot.as_posix()}"\n[floor]\nresolution = 30\n[lights]\ngrid = [2, 1, 1]\n')
    out = tmp_path / "s.zarr"
    r = lodprt("bake", scene, "-o", out, "--sh-order", "3", "--device", "cpu", "--threshold-deg", "10")
    assert r.returncode == 0, r.stderr
    info = json.loads(lodprt("info", out, "--json").stdout)
    assert info["mode"] == "cut" and info["hierarchy_nodes"] > info["vertices"]
    assert all(s["vertices_kept"] < info["vertices"] for s in info["samples"])
    png = tmp_path / "d.png"
    r = lodprt("diff", out, "--sample", "0", "--eye", "0", "1.5", "3", "--size", "160", "120", "-o", png)
    assert r.returncode == 0, r.stderr
    from PIL import Image

    img = np.asarray(Image.open(png))
    assert img.shape[1] > 3 * 160 and img.std() > 5  # three panels, not blank
    assert "relative RMSE" in r.stdout
    r = lodprt("diff", out, "--sample", "0", "--eye", "0", "1.5", "3", "-o", png)
    assert r.returncode == 2 and "already exists" in r.stderr
