"""A full disk while a store is written, and a damaged store when one is read: one line naming the store and the
array, no traceback; a full disk leaves nothing behind and the earlier store at the path as it was."""

import errno
import json
import shutil
from pathlib import Path

import numpy as np
import pytest
import zarr.storage

from lodprt.cli.main import main
from lodprt.errors import DiskFull, StoreError
from lodprt.store.bake_store import open_store
from lodprt.store.writer import ALL_CHUNKS, StoreWriter

from conftest import SPOT

FAST = ["--device", "cpu", "--sh-order", "2", "--full", "--no-hierarchy"]


def snapshot(folder):
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(Path(folder).rglob("*")) if p.is_file()}


@pytest.fixture
def spot_scene(tmp_path):
    path = tmp_path / "spot.toml"
    path.write_text(f'[[object]]\nmesh = "{SPOT.as_posix()}"\n[floor]\nresolution = 12\n[lights]\ngrid = [2, 1, 1]\n')
    return path


def full_disk(monkeypatch, where: str):
    """zarr's local store refuses (ENOSPC) the first write of a key containing ``where``."""
    real = zarr.storage.LocalStore.set

    async def refusing(self, key, value):
        if where in key:
            raise OSError(errno.ENOSPC, "No space left on device", key)
        return await real(self, key, value)

    monkeypatch.setattr(zarr.storage.LocalStore, "set", refusing)


@pytest.mark.parametrize("where, what", [("scene/normals/c", "array 'scene/normals'"),
                                         ("samples/00001/coefficients/c", "array 'samples/00001/coefficients'")])
def test_disk_full_mid_bake_is_one_line_and_leaves_the_old_store(tmp_path, spot_scene, monkeypatch, capsys, where,
                                                                   what):
    out = tmp_path / "out.zarr"
    assert main(["bake", str(spot_scene), "-o", str(out), *FAST]) == 0
    before = snapshot(out)
    capsys.readouterr()
    full_disk(monkeypatch, where)
    rc = main(["bake", str(spot_scene), "-o", str(out), *FAST, "--sh-order", "3", "--overwrite"])
    err = capsys.readouterr().err
    assert rc == 2, err
    line = [ln for ln in err.splitlines() if "error" in ln]
    assert len(line) == 1 and "Traceback" not in err
    assert "out.zarr" in line[0] and "no space left on the device" in line[0] and what in line[0]
    assert "MiB uncompressed" in line[0] and "MiB free" in line[0]
    assert snapshot(out) == before  # the earlier store, byte for byte
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.zarr", "spot.toml"]  # no partial folder left


def test_disk_full_names_the_bytes_needed(tmp_path, monkeypatch):
    """The bytes the array needed are its uncompressed size (here 3 MiB of float32)."""
    full_disk(monkeypatch, "big/c")
    with pytest.raises(DiskFull, match=r"x\.zarr: no space left on the device writing array 'big' \(needed 3\.0 MiB"):
        with StoreWriter(tmp_path / "x.zarr", overwrite=False) as w:
            w.array("big", np.zeros((262144, 3), np.float32))
    assert list(tmp_path.iterdir()) == []


def test_every_chunk_is_written_and_a_missing_one_is_damage(tmp_path):
    """All-zero chunks are stored too (zarr would skip them), so a missing chunk file is reported, not read as 0."""
    w = StoreWriter(tmp_path / "x.zarr", overwrite=False)
    w.array("zeros", np.zeros((10, 3), np.float32), chunk_rows=4)
    w.attrs(format="lodprt", format_version=1)
    path = w.commit()
    assert json.loads((path / "zarr.json").read_text())["attributes"][ALL_CHUNKS] is True
    chunks = sorted(p for p in (path / "zeros" / "c").rglob("*") if p.is_file())
    assert len(chunks) == 3  # rows 0-3, 4-7, 8-9
    from lodprt.store.reader import read_array

    root = zarr.open_group(str(path), mode="r")
    np.testing.assert_array_equal(read_array(root, path, "zeros", all_chunks=True), np.zeros((10, 3), np.float32))
    chunks[1].unlink()
    with pytest.raises(StoreError, match=r"x\.zarr: array 'zeros' is damaged, 1 of its 3 chunk files are missing; "
                                         r"inspect the store with: lodprt info"):
        read_array(root, path, "zeros", all_chunks=True)


@pytest.mark.parametrize("damage", ["garble", "delete"])
def test_damaged_chunk_is_one_line_naming_store_array_and_info(tmp_path, spot_scene, capsys, damage):
    out = tmp_path / "out.zarr"
    assert main(["bake", str(spot_scene), "-o", str(out), *FAST]) == 0
    chunk = next(p for p in sorted((out / "samples" / "00001" / "coefficients").rglob("*")) if p.is_file()
                 and p.name != "zarr.json")
    if damage == "garble":
        chunk.write_bytes(b"\x00garbled" * 7)
    else:
        chunk.unlink()
    capsys.readouterr()
    rc = main(["radiance", str(out), "--sample", "1", "--eye", "0", "1", "2", "-o", str(tmp_path / "r.npy")])
    err = capsys.readouterr().err
    assert rc == 2 and "Traceback" not in err and len(err.strip().splitlines()) == 1, err
    assert f"{out}: array 'samples/00001/coefficients' is damaged" in err
    assert ("cannot be read" if damage == "garble" else "chunk files are missing") in err
    assert f"lodprt info {out}" in err
    # what the message suggests works on the damaged store, and names the damage: a missing chunk file always, a
    # garbled one with --verify (every array read whole); status 1
    capsys.readouterr()
    assert main(["info", str(out)]) == (1 if damage == "delete" else 0)
    assert main(["info", str(out), "--verify"]) == 1
    err = capsys.readouterr().err
    assert f"{out}: damaged: array 'samples/00001/coefficients'" in err and "bake it again" in err, err
    assert len([ln for ln in err.splitlines() if "damaged: array" in ln]) == (2 if damage == "delete" else 1), err
    assert open_store(out).sample(0)[0].size > 0  # the other samples still read


def edit_json(path, **changes):
    doc = json.loads(path.read_text())
    doc.update(changes)
    path.write_text(json.dumps(doc))


@pytest.mark.parametrize("damage", ["garbled metadata", "lost metadata", "lost sample metadata", "lost array",
                                    "lost hierarchy", "garbled hierarchy", "unknown node type", "unknown data type"])
def test_info_names_a_store_part_whose_metadata_or_folder_is_gone(tmp_path, spot_scene, capsys, damage):
    """An array's zarr.json garbled or gone (zarr cannot open the array, or no longer sees it), a required array
    gone whole, the hierarchy/ group of a store baked with one gone or garbled, a zarr.json of no known node type
    or data type: info names the part in one line and exits 1, --verify too, and a run that needs the part says
    the store is damaged. (They raised JSONDecodeError or KeyError with a traceback; a lost sample array's
    metadata, a lost hierarchy and an unknown node type were called undamaged, exit 0, and the store without its
    hierarchy was said to be baked with --no-hierarchy.)"""
    out = tmp_path / "out.zarr"
    assert main(["bake", str(spot_scene), "-o", str(out), "--device", "cpu", "--sh-order", "2"]) == 0
    part, named = {"garbled metadata": ("samples/00001/coefficients", "'samples/00001/coefficients/zarr.json' "
                                        "cannot be read"),
                   "lost metadata": ("scene/positions", "'scene/positions': its zarr.json is missing"),
                   "lost sample metadata": ("samples/00001/vertex_ids", "'samples/00001/vertex_ids': its zarr.json "
                                            "is missing"),
                   "lost array": ("scene/normals", "'scene/normals' is missing"),
                   "lost hierarchy": ("hierarchy", "'hierarchy/parent' is missing"),
                   "garbled hierarchy": ("hierarchy", "'hierarchy/zarr.json' cannot be read"),
                   "unknown node type": ("scene/positions", "'scene/positions/zarr.json' names no array or group "
                                         "(node_type 'foo')"),
                   "unknown data type": ("scene/positions", "array 'scene/positions': its metadata cannot be "
                                         "read (")}[damage]
    meta = out / part / "zarr.json"
    if damage.startswith("garbled"):
        meta.write_text("{bad")
    elif damage.startswith("lost") and "metadata" in damage:
        meta.unlink()
    elif damage == "unknown node type":
        edit_json(meta, node_type="foo")
    elif damage == "unknown data type":
        edit_json(meta, data_type="bogus")
    else:
        shutil.rmtree(out / part)
    for verify in ([], ["--verify"]):
        capsys.readouterr()
        assert main(["info", str(out), *verify]) == 1, verify
        err = capsys.readouterr().err
        assert "Traceback" not in err and f"{out}: damaged: {named}" in err and "bake it again" in err, err
    if damage in ("lost hierarchy", "garbled hierarchy"):
        with pytest.raises(StoreError, match=r"'hierarchy' (is missing|cannot be read .*): the store is damaged"):
            open_store(out).hierarchy()
    capsys.readouterr()
    assert main(["info", str(out), "--json"]) == 1
    assert named in " ".join(json.loads(capsys.readouterr().out)["damage"])


def test_info_verify_of_an_intact_store_and_of_a_transfer_store(tmp_path, spot_scene, capsys):
    """An intact store: info and info --verify exit 0 and report no damage (JSON: "damage": []); a transfer store
    with a chunk file gone: info names it and exits 1."""
    out = tmp_path / "out.zarr"
    assert main(["bake", str(spot_scene), "-o", str(out), *FAST]) == 0
    capsys.readouterr()
    assert main(["info", str(out), "--verify", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["damage"] == []
    env = tmp_path / "env.zarr"
    assert main(["bake-environment", str(spot_scene), "-o", str(env), "--rays", "16", "--sh-order", "2"]) == 0
    chunk = next(p for p in sorted((env / "transfer").rglob("*")) if p.is_file() and p.name != "zarr.json")
    chunk.unlink()
    capsys.readouterr()
    assert main(["info", str(env)]) == 1
    assert "damaged: array 'transfer" in capsys.readouterr().err


def test_disk_full_outside_a_store_is_one_line_naming_the_output(tmp_path, spot_scene, monkeypatch, capsys):
    """ENOSPC anywhere else (here numpy writing lodprt radiance's .npy) is one line naming the output, status 2."""
    out = tmp_path / "out.zarr"
    assert main(["bake", str(spot_scene), "-o", str(out), *FAST]) == 0
    capsys.readouterr()
    rad = tmp_path / "r.npy"

    def refuse(*_a, **_k):
        raise OSError(errno.ENOSPC, "No space left on device", str(rad))

    monkeypatch.setattr(np, "save", refuse)
    rc = main(["radiance", str(out), "--sample", "0", "--eye", "0", "1", "2", "-o", str(rad)])
    err = capsys.readouterr().err
    assert rc == 2 and "Traceback" not in err and len(err.strip().splitlines()) == 1, err
    assert f"{rad}: no space left on the device" in err


def test_a_hierarchy_with_a_broken_link_is_refused_naming_store_and_node(tmp_path, spot_scene):
    """A stored hierarchy whose node claims a parent that does not list it (what a stale row of the tiled sequential
    build once left behind: the run time's forced refinement then never ended) is refused when read, naming the
    store, the group and the node."""
    out = tmp_path / "out.zarr"
    assert main(["bake", str(spot_scene), "-o", str(out), "--device", "cpu", "--sh-order", "2"]) == 0
    h = open_store(out).hierarchy()
    root = int(h.roots[-1])
    assert root >= h.num_vertices  # an internal root
    parent = zarr.open_array(str(out / "hierarchy" / "parent"), mode="r+")
    parent[root] = root - 1  # a node made before it, whose children are others
    with pytest.raises(StoreError, match=rf"out\.zarr: hierarchy/: hierarchy arrays inconsistent: node {root} has "
                                         r"parent"):
        open_store(out).hierarchy()


def test_a_lost_sample_group_or_attribute_is_named(spot_scene, tmp_path, capsys):
    """A sample group deleted, a sample's statistics or the lights' intensity attribute removed: info (damage,
    status 1, the attribute too), compress, radiance and export say which group or attribute is gone (they raised KeyError), and bake
    --resume or
    --add-samples call the store damaged, leaving no partial folder behind (one blocked the next bake)."""
    store = tmp_path / "s.zarr"
    assert main(["bake", str(spot_scene), "-o", str(store), *FAST]) == 0
    lost = tmp_path / "lost.zarr"
    lost.mkdir()
    for name, data in snapshot(store).items():  # a copy with samples/00001 gone
        if not name.startswith("samples/00001"):
            (lost / name).parent.mkdir(parents=True, exist_ok=True)
            (lost / name).write_bytes(data)
    capsys.readouterr()
    assert main(["info", str(lost)]) == 1  # info reports the damage (status 1), the others refuse the store (2)
    assert f"{lost}: damaged: 'samples/00001' is missing" in capsys.readouterr().err
    for argv in (["compress", str(lost), "-o", str(tmp_path / "c.zarr"), "--codec", "f16"],
                 ["radiance", str(lost), "--sample", "1", "--eye", "0", "1", "3", "-o", str(tmp_path / "r.npy")]):
        assert main(argv) == 2, argv
        err = capsys.readouterr().err
        assert "samples/00001" in err and "is missing" in err and len(err.strip().splitlines()) == 1, (argv, err)
    bigger = spot_scene.with_name("bigger.toml")
    bigger.write_text(spot_scene.read_text().replace("grid = [2, 1, 1]", "grid = [6, 1, 1]"))
    for argv in (["bake", str(spot_scene), "-o", str(lost), "--resume", *FAST],
                 ["bake", str(bigger), "-o", str(lost), "--add-samples", *FAST]):
        assert main(argv) == 2, argv
        assert "samples/00001 missing or incomplete: the store is damaged" in capsys.readouterr().err, argv
    assert sorted(p.name for p in tmp_path.iterdir() if p.name.startswith("lost")) == ["lost.zarr"]
    for group, key in (("samples/00000", "vertices_kept"), ("lights", "intensity")):
        meta = store / group / "zarr.json"
        doc = json.loads(meta.read_text())
        del doc["attributes"][key]
        meta.write_text(json.dumps(doc))
        argv = ["info", str(store)] if key == "vertices_kept" else \
            ["radiance", str(store), "--sample", "0", "--eye", "0", "1", "3", "-o", str(tmp_path / "q.npy")]
        assert main(argv) == (1 if key == "vertices_kept" else 2)  # info: damage, as for a missing array
        want = f"{store}: damaged: samples/00000: attribute(s) vertices_kept missing" if key == "vertices_kept" \
            else "lights: attribute(s) intensity missing"
        assert want in capsys.readouterr().err


def test_a_store_under_a_file_is_refused_in_one_line(tmp_path, spot_scene, capsys):
    """-o FILE/x.zarr (a parent that is a file): bake, bake --compress and compress say so in one line, status 2,
    and leave nothing (making the partial folder raised NotADirectoryError with a traceback)."""
    store = tmp_path / "s.zarr"
    assert main(["bake", str(spot_scene), "-o", str(store), *FAST]) == 0
    afile = tmp_path / "afile"
    afile.write_text("mine")
    out = afile / "x.zarr"
    for argv in (["bake", str(spot_scene), "-o", str(out), *FAST], ["bake", str(spot_scene), "-o", str(out), *FAST,
                 "--compress", "f16"], ["compress", str(store), "-o", str(out), "--codec", "f16"]):
        capsys.readouterr()
        assert main(argv) == 2, argv
        err = capsys.readouterr().err
        assert f"{out}: the folder {afile} is a file, not a folder" in err and "Traceback" not in err, err
        assert len([ln for ln in err.splitlines() if "error" in ln]) == 1, err
    assert afile.read_text() == "mine" and sorted(p.name for p in tmp_path.iterdir()) == ["afile", "s.zarr",
                                                                                         "spot.toml"]


@pytest.mark.parametrize("root", ["null", '{"zarr_format": 3, "node_type": "group", "attributes": null}'])
def test_a_root_zarr_json_of_no_group_is_not_a_store(tmp_path, spot_scene, capsys, root):
    """A root zarr.json that is JSON but no group's (null, attributes null): one line, status 2, "not a lodprt
    store" (it raised AttributeError with a traceback)."""
    out = tmp_path / "out.zarr"
    assert main(["bake", str(spot_scene), "-o", str(out), *FAST]) == 0
    (out / "zarr.json").write_text(root)
    capsys.readouterr()
    assert main(["info", str(out)]) == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err and "not a lodprt store" in err and len(err.strip().splitlines()) == 1, err


def test_info_of_a_store_without_its_mode_attribute(tmp_path, spot_scene, capsys):
    """The root's mode attribute removed: info prints the summary with mode None (it raised TypeError adding
    None to a string)."""
    out = tmp_path / "out.zarr"
    assert main(["bake", str(spot_scene), "-o", str(out), *FAST]) == 0
    doc = json.loads((out / "zarr.json").read_text())
    del doc["attributes"]["mode"]
    (out / "zarr.json").write_text(json.dumps(doc))
    capsys.readouterr()
    assert main(["info", str(out)]) == 0
    assert "(None)" in capsys.readouterr().out


@pytest.fixture(scope="module")
def pristine(tmp_path_factory):
    """Intact stores of each kind the tests below damage, baked once (they damage copies, ``copy_of``): a full and
    a light-cut point-light store, f16, q8 and cpca re-encodings of the full one, q8 of the cut one, a transfer
    store, a LOD transfer store and a volume store with a stored lighting."""
    d = tmp_path_factory.mktemp("pristine")
    scene = d / "spot.toml"
    scene.write_text(f'[[object]]\nmesh = "{SPOT.as_posix()}"\n[floor]\nresolution = 12\n[lights]\ngrid = [2, 1, 1]\n')
    assert main(["bake", str(scene), "-o", str(d / "full.zarr"), *FAST]) == 0
    assert main(["bake", str(scene), "-o", str(d / "cut.zarr"), "--device", "cpu", "--sh-order", "2"]) == 0
    from lodprt.store.compress import compress_store

    for source, codec, name in (("full", "f16", "f16"), ("full", "q8", "q8"), ("full", "cpca:4:2", "cpca"),
                                ("cut", "q8", "cut_q8")):
        compress_store(d / f"{source}.zarr", d / f"{name}.zarr", codec)
    env = ["bake-environment", str(scene), "--rays", "16", "--sh-order", "2", "--device", "cpu"]
    assert main([*env, "-o", str(d / "env.zarr")]) == 0
    assert main([*env, "-o", str(d / "env_lod.zarr"), "--lod-threshold", "0.05"]) == 0
    assert main(["bake-volume", "cloud:8", "-o", str(d / "volume.zarr"), "--rays", "8", "--bounces", "0",
                 "--environment", "sky:16", "--device", "cpu"]) == 0
    return d


def copy_of(pristine, kind: str, tmp_path) -> Path:
    out = tmp_path / f"{kind}.zarr"
    shutil.copytree(pristine / f"{kind}.zarr", out)
    return out


def info_damage(capsys, out) -> list[str]:
    """The damage lines of ``lodprt info`` and ``info --verify`` of ``out`` (the same in both), each exiting 1."""
    lines = []
    for verify in ([], ["--verify"]):
        capsys.readouterr()
        assert main(["info", str(out), *verify]) == 1, verify
        err = capsys.readouterr().err
        assert "Traceback" not in err and "bake it again" in err, err
        lines.append([ln for ln in err.splitlines() if ": damaged: " in ln])
    assert lines[0] == lines[1]
    return lines[0]


@pytest.mark.parametrize("kind", ["full", "cut", "f16", "q8", "cpca", "cut_q8", "env", "env_lod", "volume"])
def test_intact_stores_of_every_kind_pass_info_verify(pristine, capsys, kind):
    """No store a bake (or compress) writes is called damaged by the checks of the parts and attributes it wrote."""
    capsys.readouterr()
    assert main(["info", str(pristine / f"{kind}.zarr"), "--verify", "--json"]) == 0, capsys.readouterr().err
    assert json.loads(capsys.readouterr().out)["damage"] == []


def test_open_arrays_is_the_one_opening_of_reader_damage_and_summary(pristine, tmp_path, monkeypatch):
    """``reader.open_arrays`` opens the arrays walk found for both ``reader.damage`` and ``FormatStore.summary``
    (each had its own try/except): an array of a data type zarr does not read is left out of the summary's arrays
    and named once in its damage."""
    from lodprt.store import reader
    from lodprt.store.transfer_store import TransferStore

    out = copy_of(pristine, "env", tmp_path)
    edit_json(out / "transfer" / "diffuse" / "zarr.json", data_type="bogus")
    root = zarr.open_group(str(out), mode="r")
    names = reader.walk(out)[0]
    opened, problems = reader.open_arrays(root, names)
    assert sorted(opened) == [n for n in names if n != "transfer/diffuse"]
    assert len(problems) == 1 and problems[0].startswith("array 'transfer/diffuse': its metadata cannot be read (")
    calls = []
    real = reader.open_arrays
    monkeypatch.setattr(reader, "open_arrays", lambda r, n: calls.append(list(n)) or real(r, n))
    summary = TransferStore(out).summary()
    assert calls == [names, names] and "transfer/diffuse" not in summary["arrays"]
    assert [line for line in summary["damage"] if "transfer/diffuse" in line] == problems


@pytest.mark.parametrize("kind, part", [
    ("full", "samples/00001/coefficients"), ("full", "samples/00000/vertex_ids"), ("full", "scene/object_id"),
    ("full", "scene/material_id"), ("full", "materials/ks"), ("cut", "samples/00001/dark"),
    ("cut", "samples/00000/cut_nodes"), ("f16", "samples/00000/coefficients_f16"),
    ("q8", "samples/00001/band_scales"), ("q8", "samples/00000/vertex_gaps_long"), ("cpca", "codec/basis"),
    ("cpca", "samples/00000/weights"), ("cut_q8", "samples/00001/cut_levels")])
def test_a_lost_array_of_a_sample_group_scene_or_codec_is_damage(pristine, tmp_path, capsys, kind, part):
    """An array the bake (or compress) wrote, deleted whole: a sample's coefficients or ids, its codec's arrays, the
    cut's, a cpca model's, the scene's ids and the materials: info and info --verify name it, once, and exit 1
    (they called the store intact, and render then named the missing field)."""
    out = copy_of(pristine, kind, tmp_path)
    shutil.rmtree(out / part)
    assert info_damage(capsys, out) == [f"{out}: damaged: '{part}' is missing"]


@pytest.mark.parametrize("kind, part", [
    ("env", "materials/mirror"), ("env", "transfer/glossy_vertex_ids"), ("env", "scene/material_id"),
    ("env", "transfer/diffuse"), ("env_lod", "transfer/cut_nodes"), ("env_lod", "hierarchy/parent"),
    ("env_lod", "transfer/glossy_kept_ids"), ("volume", "volume/density"), ("volume", "transfer/vectors"),
    ("volume", "environment/coefficients")])
def test_a_lost_array_of_a_transfer_or_volume_store_is_damage(pristine, tmp_path, capsys, kind, part):
    """Transfer and volume stores check the arrays their bake wrote too (they had no such check: exit 0)."""
    out = copy_of(pristine, kind, tmp_path)
    shutil.rmtree(out / part)
    assert info_damage(capsys, out) == [f"{out}: damaged: '{part}' is missing"]


@pytest.mark.parametrize("kind, group, key", [
    ("cut", "lights", "box"), ("cut", "hierarchy", "roots"), ("full", "samples/00001", "vertices_kept"),
    ("full", "", "sh_order"), ("f16", "samples/00000", "scale_exponent"), ("q8", "samples/00001", "band_bits"),
    ("cpca", "codec", "weight_levels"), ("f16", "", "codec"), ("volume", "volume", "albedo"),
    ("env", "", "sh_order")])
def test_a_lost_attribute_is_damage(pristine, tmp_path, capsys, kind, group, key):
    """A required attribute removed (the light box, the hierarchy's roots, a sample's statistics or its codec's
    scale, the root's SH order or codec, a volume's albedo): info and info --verify list it as damage and exit 1
    (info stopped with a one-line error, status 2, or called the store intact)."""
    out = copy_of(pristine, kind, tmp_path)
    meta = out / group / "zarr.json"
    doc = json.loads(meta.read_text())
    del doc["attributes"][key]
    meta.write_text(json.dumps(doc))
    assert info_damage(capsys, out) == [f"{out}: damaged: {group or 'root'}: attribute(s) {key} missing"]
    capsys.readouterr()
    assert main(["info", str(out), "--json"]) == 1
    assert f"{group or 'root'}: attribute(s) {key} missing" in json.loads(capsys.readouterr().out)["damage"]


def test_a_bogus_or_lost_codec_attribute(pristine, tmp_path, capsys):
    """A compressed store whose root codec names no codec is damage (it passed info --verify); without the
    attribute, reading it is a StoreError naming the store and the attribute (it raised KeyError 'coefficients'
    in Store.coefficients_per_vertex), radiance one line with status 2."""
    out = copy_of(pristine, "f16", tmp_path)
    meta = out / "zarr.json"
    edit_json(meta, attributes={**json.loads(meta.read_text())["attributes"], "codec": "bogus"})
    assert info_damage(capsys, out) == [f"{out}: damaged: root: attribute codec 'bogus' names no codec this lodprt "
                                        "reads"]
    with pytest.raises(StoreError, match=r"f16\.zarr: root: attribute codec 'bogus' names no codec"):
        open_store(out).sample(0)
    doc = json.loads(meta.read_text())
    del doc["attributes"]["codec"]
    meta.write_text(json.dumps(doc))
    with pytest.raises(StoreError, match=r"f16\.zarr: root: attribute\(s\) codec missing: the store is damaged"):
        open_store(out).coefficients_per_vertex
    capsys.readouterr()
    assert main(["radiance", str(out), "--sample", "0", "--eye", "0", "1", "3", "-o", str(tmp_path / "r.npy")]) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and f"{out}: root: attribute(s) codec missing" in err, err
