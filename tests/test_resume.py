"""Resumable and extensible bakes (docs/DISTRIBUTED.md, docs/FORMAT.md "Completion marks, resumed and extended
bakes"): a bake killed with SIGKILL and resumed, and a store extended with --add-samples, equal an uninterrupted
bake of the same scene array for array, byte for byte; other settings are refused by name."""

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from lodprt.errors import LodprtError, StoreError
from lodprt.model.scene import load_scene
from lodprt.precompute.bake import bake
from lodprt.store.bake_store import open_store
from lodprt.store.writer import OWNER_FILE, process_identity
from lodprt.store.resume import TIMINGS
from lodprt.store.sample_groups import SampleGroupWriter, complete_samples, is_complete, tidy

from conftest import SPOT

REPO = Path(__file__).resolve().parents[1]
#: the attributes allowed to differ, written out here (not taken from the code under test), by group
TIMING = {"": {"bake_seconds", "load_seconds", "hierarchy_seconds"}, "hierarchy": {"seconds"}, "samples": {"seconds"}}
FAST = ["--device", "cpu", "--sh-order", "2", "--threshold-deg", "5"]


def scene_file(tmp_path, grid=(4, 1, 4), box=None, name="scene.toml", floor=12):
    """spot on a small floor (about 3,100 vertices): every sample bakes in tens of milliseconds."""
    lights = f"grid = {list(grid)}" + ("" if box is None else f"\nbox = {list(box)}")
    path = tmp_path / name
    path.write_text(f'[[object]]\nmesh = "{SPOT.as_posix()}"\n[floor]\nresolution = {floor}\n[lights]\n{lights}\n')
    return path


def api_bake(toml, out, **kw):
    """The in-process reference: the same settings as FAST."""
    return bake(load_scene(str(toml)), out, sh_order=2, device="cpu", threshold_deg=5.0, **kw)


def lodprt(*args):
    return [sys.executable, "-m", "lodprt.cli.main", *map(str, args)]


def files(folder):
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(Path(folder).rglob("*")) if p.is_file()}


def assert_same_store(a, b):
    """Every file of the two stores byte-identical, but for the timing attributes of group zarr.json files
    (arrays: chunk files and array metadata, i.e. values, dtype, shape and chunking, compared byte for byte)."""
    fa, fb = files(a), files(b)
    assert sorted(fa) == sorted(fb), set(fa) ^ set(fb)
    for name in fa:
        if fa[name] == fb[name]:
            continue
        assert name.endswith("zarr.json"), f"{name} differs"
        ja, jb = json.loads(fa[name]), json.loads(fb[name])
        assert ja["node_type"] == "group", f"{name} differs"
        group = str(Path(name).parent)
        allowed = TIMING.get("samples" if group.startswith("samples/") else "" if group == "." else group, set())
        assert {k: v for k, v in ja.items() if k != "attributes"} == {k: v for k, v in jb.items() if k != "attributes"}
        strip = lambda d: {k: v for k, v in d["attributes"].items() if k not in allowed}  # noqa: E731
        assert strip(ja) == strip(jb), f"{name}: attributes other than {sorted(allowed)} differ"


def test_timing_attributes_documented():
    """The code's list of attributes that may differ is the one these tests (and docs/FORMAT.md) allow."""
    code = {("" if g == "/" else "samples" if g.startswith("samples") else g): set(v) for g, v in TIMINGS.items()}
    assert code == TIMING
    doc = (REPO / "docs" / "FORMAT.md").read_text()
    assert all(f"`{name}`" in doc for names in TIMING.values() for name in names)


def test_sample_group_writer_marks_and_moves(tmp_path):
    """A sample group appears whole with its mark last; a second writer of the same sample keeps the first copy;
    tidy removes scratch and zarr's temporary files; a group without a mark does not count."""
    import zarr

    partial = tmp_path / "p.zarr"
    zarr.open_group(str(partial), mode="w", zarr_format=3).require_group("samples")
    first = SampleGroupWriter(partial, 3)
    first.array("samples/00003/vertex_ids", np.arange(5, dtype=np.int32))
    assert not (partial / "samples" / "00003").exists()  # nothing in samples/ before finish
    first.attrs("samples/00003", vertices_kept=5)
    assert first.finish() and is_complete(partial / "samples" / "00003")
    second = SampleGroupWriter(partial, 3)
    second.array("samples/00003/vertex_ids", np.zeros(5, np.int32))
    assert not second.finish()  # someone finished it first: that copy stays
    assert (open_store_array(partial, "samples/00003/vertex_ids") == np.arange(5)).all()
    (partial / "samples" / "00004").mkdir()  # killed by an older writer before its mark
    (partial / "samples" / "00004" / "zarr.json").write_text('{"attributes": {}, "zarr_format": 3, "node_type": "group"}')
    assert complete_samples(partial, 6) == [3]
    stray = SampleGroupWriter(partial, 5)  # killed mid-write: left under .writing
    (partial / "scene.0123456789abcdef0123456789abcdef.partial").write_text("x")
    assert stray.scratch.exists() and tidy(partial) == 2
    assert not (partial / ".writing").exists() and not list(partial.glob("*.partial"))


def open_store_array(folder, name):
    import zarr

    return zarr.open_group(str(folder), mode="r")[name][...]


def kill_at(cmd, partial_glob, ready, deadline=60.0):
    """Start ``cmd``, wait until its partial folder satisfies ``ready(folder)``, SIGKILL it; returns the folder."""
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        end = time.monotonic() + deadline
        folder = None
        while proc.poll() is None and time.monotonic() < end:
            found = list(Path(partial_glob.parent).glob(partial_glob.name))
            if found and ready(found[0]):
                folder = found[0]
                break
            time.sleep(0.005)
        assert proc.poll() is None and folder is not None, "the bake finished (or failed) before the kill point"
        os.kill(proc.pid, signal.SIGKILL)
    finally:
        proc.kill()
        proc.wait()
    assert proc.returncode == -signal.SIGKILL
    return folder


def hierarchy_building(folder):
    """The bake has made its partial folder (owner record first) and not yet written its scene: it is loading the
    kernels or building the hierarchy, which come before the scene and the hierarchy are written (a window of
    about a second, where the one after the scene's completion mark lasts milliseconds and a loaded machine let
    the bake finish inside it)."""
    return (folder / OWNER_FILE).is_file() and not is_complete(folder / "scene")


def samples_half_done(folder):
    return len(complete_samples(folder, 16)) >= 4


def test_sigkill_then_resume_is_byte_identical(tmp_path):
    """kill -9 while the hierarchy is built, --resume killed again after some samples, --resume again: the store
    equals an uninterrupted bake, and the finished samples of the killed runs were kept, not baked again."""
    toml = scene_file(tmp_path)
    ref = tmp_path / "ref.zarr"
    api_bake(toml, ref)
    out = tmp_path / "out.zarr"
    cmd = lodprt("bake", toml, "-o", out, *FAST, "--jobs", "1")
    first = kill_at(cmd, tmp_path / "out.zarr.partial-*", hierarchy_building)
    assert (first / OWNER_FILE).is_file() and not out.exists() and not complete_samples(first, 16)
    second = kill_at(cmd + ["--resume"], tmp_path / "out.zarr.partial-*", samples_half_done)
    assert not first.exists()  # adopted: renamed to the resuming process' partial folder
    kept = complete_samples(second, 16)
    r = subprocess.run(cmd + ["--resume"], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.zarr", "ref.zarr", "scene.toml"]
    assert_same_store(ref, out)
    assert f"{len(kept)} of 16 light samples were already in the store" in r.stderr


def dead_partial(store, dest):
    """Turn the committed ``store`` into what a killed bake of ``dest`` leaves: a partial folder of a dead pid."""
    p = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    owner = process_identity(p.pid)
    p.kill()
    p.wait()
    folder = dest.with_name(f"{dest.name}.partial-{owner['pid']}")
    store.rename(folder)
    (folder / OWNER_FILE).write_text(json.dumps(owner))
    return folder


def test_resume_refuses_other_settings_and_scene(tmp_path):
    """--resume with another setting or another scene names what differs and leaves the interrupted bake alone;
    a finished store is left untouched, and without --resume nothing is adopted."""
    toml = scene_file(tmp_path, grid=(2, 1, 1))
    out = tmp_path / "out.zarr"
    api_bake(toml, tmp_path / "done.zarr")
    partial = dead_partial(tmp_path / "done.zarr", out)
    before = files(partial)
    scene = load_scene(str(toml))
    with pytest.raises(LodprtError, match="setting sh_order is 2 there but 3 now"):
        bake(scene, out, sh_order=3, device="cpu", threshold_deg=5.0, resume=True)
    with pytest.raises(LodprtError, match="setting threshold_deg is 5.0 there but 10.0 now"):
        bake(scene, out, sh_order=2, device="cpu", threshold_deg=10.0, resume=True)
    with pytest.raises(LodprtError, match=r"setting lights\.grid is \[2, 1, 1\] there but \[1, 1, 2\] now"):
        api_bake(scene_file(tmp_path, grid=(1, 1, 2), name="other-grid.toml"), out, resume=True)
    with pytest.raises(LodprtError, match="fingerprint of positions, normals, faces, material_id, object_id"):
        api_bake(scene_file(tmp_path, grid=(2, 1, 1), floor=13, name="bigger-floor.toml"), out, resume=True)
    assert files(partial) == before and not out.exists()
    res = api_bake(toml, out, resume=True)  # the same settings: adopted and committed, nothing baked again
    assert res.reused_samples == 2 and not partial.exists()
    committed = files(out)
    res = api_bake(toml, out, resume=True)  # a finished store: nothing to do, nothing written
    assert res.reused_samples == 2 and files(out) == committed
    with pytest.raises(LodprtError, match="setting sh_order"):
        bake(scene, out, sh_order=3, device="cpu", threshold_deg=5.0, resume=True)


def test_add_samples_equals_fresh_bake_of_the_bigger_grid(tmp_path):
    """--add-samples from a 1 x 1 x 1 grid to 3 x 1 x 3 over the same box, then to a box twice as deep (3 x 1 x 6,
    the same cells): each step equals a fresh bake of the final grid, reuses every old sample (their groups byte
    for byte) and the run time's light interpolation reads the same positions and box."""
    from lodprt.runtime.lights import LightInterpolator

    box = (-1.0, 1.5, -1.0, 1.0, 2.5, 1.0)
    steps = [((1, 1, 1), box), ((3, 1, 3), box), ((3, 1, 6), box[:5] + (3.0,))]
    out = tmp_path / "grown.zarr"
    for n, (grid, b) in enumerate(steps):
        toml = scene_file(tmp_path, grid=grid, box=b, name=f"step{n}.toml")
        if n == 0:
            api_bake(toml, out)
            continue
        old = open_store(out)
        old_groups = {tuple(p): files(out / "samples" / f"{k:05d}") for k, p in enumerate(old.light_positions)}
        res = api_bake(toml, out, add_samples=True)
        assert res.reused_samples == len(old_groups)
        fresh = tmp_path / f"fresh{n}.zarr"
        api_bake(toml, fresh)
        assert_same_store(fresh, out)
        grown = open_store(out)
        for k, p in enumerate(grown.light_positions):  # the same light position carries the same sample
            if tuple(p) in old_groups:
                strip = {name: data for name, data in old_groups[tuple(p)].items() if name != "zarr.json"}
                assert strip == {name: data for name, data in files(out / "samples" / f"{k:05d}").items()
                                 if name != "zarr.json"}
        light = np.array([[0.3, 2.0, 0.7]])
        w_fresh = LightInterpolator(open_store(fresh).light_positions, b).weights(light)
        w_grown = LightInterpolator(grown.light_positions, grown.root["lights"].attrs["box"]).weights(light)
        assert all((x == y).all() for x, y in zip(w_fresh, w_grown))


def test_an_extension_asking_another_hierarchy_build_says_it_keeps_the_stores(tmp_path, caplog):
    """--add-samples (as --resume) keeps the store's hierarchy, which its samples were cut on: asking another
    build (here rounds on a sequential store) is said in a warning naming both, not ignored without a word."""
    box = (-1.0, 1.5, -1.0, 1.0, 2.5, 1.0)
    out = tmp_path / "s.zarr"
    api_bake(scene_file(tmp_path, grid=(1, 1, 1), box=box, name="a.toml"), out)
    assert open_store(out).hierarchy().method == "sequential"
    with caplog.at_level("WARNING", logger="lodprt.precompute.bake"):
        api_bake(scene_file(tmp_path, grid=(3, 1, 1), box=box, name="b.toml"), out, add_samples=True,
                 hierarchy_method="rounds")
    assert "keeps the hierarchy it was baked with (sequential), not a rounds build" in caplog.text
    assert open_store(out).hierarchy().method == "sequential"


def test_add_samples_refuses_a_grid_without_the_old_samples(tmp_path):
    """A grid that does not contain every old position (2 -> 4 cells over the same box: cell centres move) is
    refused before any work, naming the sample; --add-samples without a store says there is none."""
    box = (-1.0, 1.5, -1.0, 1.0, 2.5, 1.0)
    out = tmp_path / "s.zarr"
    api_bake(scene_file(tmp_path, grid=(2, 1, 1), box=box, name="a.toml"), out)
    before = files(out)
    with pytest.raises(LodprtError, match=r"light sample 0 at \[-0\.5, 2\.0, 0\.0\] is not a position of the new grid"):
        api_bake(scene_file(tmp_path, grid=(4, 1, 1), box=box, name="b.toml"), out, add_samples=True)
    with pytest.raises(StoreError, match="--add-samples extends an existing store, and there is none"):
        api_bake(scene_file(tmp_path, grid=(4, 1, 1), box=box, name="b.toml"), tmp_path / "none.zarr",
                 add_samples=True)
    assert files(out) == before and sorted(p.name for p in tmp_path.iterdir()) == ["a.toml", "b.toml", "s.zarr"]


def test_resume_with_compress_encodes_a_finished_float32_store(tmp_path):
    """bake --compress killed while re-encoding leaves the finished float32 store; the same bake with --resume now
    encodes it (it reported success and left it float32); resumed again it is finished; another codec is refused
    naming both, and --add-samples refuses an encoded store naming its codec (it blamed format_version)."""
    from lodprt.store.bake_store import open_store

    toml = scene_file(tmp_path, grid=(2, 1, 1))
    out = tmp_path / "out.zarr"
    api_bake(toml, out)
    assert open_store(out).codec == "none"
    api_bake(toml, out, resume=True, compress="q8")
    assert open_store(out).codec == "q8"
    before = files(out)
    api_bake(toml, out, resume=True, compress="q8")  # finished and encoded: nothing written
    assert files(out) == before
    with pytest.raises(LodprtError, match="holds this bake encoded with codec q8, not q10"):
        api_bake(toml, out, resume=True, compress="q10")
    with pytest.raises(LodprtError, match="is encoded with codec q8; --add-samples extends a float32 store"):
        api_bake(scene_file(tmp_path, grid=(6, 1, 1), name="more.toml"), out, add_samples=True)
    assert files(out) == before


def test_resume_without_compress_leaves_a_finished_encoded_store(tmp_path, caplog, capsys):
    """`bake --compress q8` then `bake --resume` (no --compress) said 'nothing to do' and then failed with exit 2
    'holds this bake encoded with codec q8, not none'. A finished store is left as it is, exit 0, its codec named;
    another codec asked is refused with the codec error alone, before any 'nothing to do'."""
    from lodprt.cli.main import main

    toml = scene_file(tmp_path, grid=(2, 1, 1))
    out = tmp_path / "g.zarr"
    assert main(["bake", str(toml), "-o", str(out), *FAST, "--compress", "q8"]) == 0
    before = files(out)
    caplog.clear()
    capsys.readouterr()
    assert main(["bake", str(toml), "-o", str(out), *FAST, "--resume"]) == 0
    assert "already holds every light sample of this bake (encoded with codec q8, left as it is); nothing to do" \
        in caplog.text
    assert files(out) == before and open_store(out).codec == "q8"
    caplog.clear()
    capsys.readouterr()
    assert main(["bake", str(toml), "-o", str(out), *FAST, "--resume", "--compress", "q10"]) == 2
    assert "holds this bake encoded with codec q8, not q10" in capsys.readouterr().err
    assert "nothing to do" not in caplog.text and files(out) == before
