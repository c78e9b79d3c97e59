"""The default white recorded at bake time (docs/FORMAT.md "Default white", ``lodprt.store.white``): equal to the
full scan of every sample's rows on grey and RGB, cut and full stores, after a resumed, extended, distributed or
re-encoded bake; a Runtime opening a store with the record reads no sample for it. And the bake's memory does not
grow with the number of light samples (docs/SCALE.md)."""

import json
import shutil
import tracemalloc

import pytest

import lodprt.store.white as white_module
from lodprt.model.scene import THESIS_MATERIAL, Material, assemble_scene, load_mesh
from lodprt.precompute.bake import bake
from lodprt.runtime.samples import default_white
from lodprt.store.bake_store import Store, open_store, sample_group
from lodprt.store.compress import compress_store
from lodprt.store.white import RECORD_KEYS, WHITE

from conftest import SPOT
from test_resume import api_bake, dead_partial, scene_file

RGB = Material((0.9, 0.3, 0.1), 0.4, 20.0)


def scanned(path) -> float:
    """The white of the store at ``path`` by the full scan (the record hidden from ``default_white``)."""
    store = open_store(path)
    store.attrs.pop(WHITE, None)
    return default_white(store)


def spot_scene(material=THESIS_MATERIAL, grid=(3, 2, 3), floor=10):
    pos, faces = load_mesh(SPOT)
    return assemble_scene([("spot", pos, faces, material)], (floor, 1.0, THESIS_MATERIAL), {"grid": list(grid)},
                          "lights", "spot")


def drop_records(path) -> None:
    """Make ``path`` look baked before the record: no root white, no sample records."""
    for doc in [path / "zarr.json", *sorted((path / "samples").glob("*/zarr.json"))]:
        j = json.loads(doc.read_text())
        for key in (WHITE, *RECORD_KEYS):
            j["attributes"].pop(key, None)
        doc.write_text(json.dumps(j))


@pytest.mark.parametrize("colour, mode, divisor", [("grey", "cut", None), ("rgb", "cut", None),
                                                   ("grey", "full", None), ("rgb", "full", 10 ** 9),
                                                   ("grey", "cut", 1)])
def test_recorded_white_equals_the_full_scan(tmp_path, monkeypatch, colour, mode, divisor):
    """Exact equality: records of the default size, of 2 values (the samples whose records stop too high are read
    again at the commit) and of every value (divisor 1)."""
    if divisor is not None:
        monkeypatch.setattr(white_module, "TOP_DIVISOR", divisor)
    scene = spot_scene(RGB if colour == "rgb" else THESIS_MATERIAL)
    out = tmp_path / "s.zarr"
    res = bake(scene, out, sh_order=2, device="cpu", threshold_deg=None if mode == "full" else 5.0)
    store = open_store(out)
    assert store.num_samples == 18 and int(store.attrs["channels"]) == (3 if colour == "rgb" else 1)
    recorded = store.attrs[WHITE]
    assert recorded == scanned(out) and default_white(store) == recorded
    assert not any(k in info for info in res.samples for k in RECORD_KEYS)  # statistics only, not the record
    assert len(store.sample_info(0)["white_top"]) <= store.sample_info(0)["white_count"] // 64 + 2 or divisor


def test_runtime_open_reads_no_sample_for_the_white(tmp_path, monkeypatch):
    """With the record, opening reads at most the samples the first light uses (completed: ``samples.completed``;
    none on a direct-only store, whose slots are drawn from D_j V_j, M-1); without it (an older store), every sample
    once more."""
    from lodprt.runtime.session import Runtime

    out = tmp_path / "s.zarr"
    bake(spot_scene(grid=(3, 3, 3)), out, sh_order=2, device="cpu")
    reads = []
    original = Store.sample
    monkeypatch.setattr(Store, "sample", lambda self, k: reads.append(k) or original(self, k))
    rt = Runtime(open_store(out), device="cpu", lod=False)
    assert len(reads) <= rt.samples.completed < 27
    assert rt.white == open_store(out).attrs[WHITE]
    old = tmp_path / "old.zarr"
    shutil.copytree(out, old)
    drop_records(old)
    reads.clear()
    rt_old = Runtime(open_store(old), device="cpu", lod=False)
    assert 27 <= len(reads) <= 27 + rt_old.samples.completed and rt_old.white == rt.white


def test_bad_recorded_white_names_the_store(tmp_path):
    from lodprt.errors import StoreError

    out = tmp_path / "s.zarr"
    bake(spot_scene(grid=(1, 1, 2)), out, sh_order=1, device="cpu")
    store = open_store(out)
    store.attrs[WHITE] = "bright"
    with pytest.raises(StoreError, match=f"s.zarr: root attribute {WHITE}"):
        default_white(store)


def test_white_after_resume_extension_and_compression(tmp_path):
    """--resume (a killed bake's partial folder, some samples missing), --add-samples (from a store baked before
    the record) and compress (the decoded rows of a lossy codec) each record the white of their rows."""
    toml = scene_file(tmp_path, grid=(3, 1, 3))
    ref = tmp_path / "ref.zarr"
    api_bake(toml, ref)
    want = open_store(ref).attrs[WHITE]
    assert want == scanned(ref)
    # resume: a killed bake's folder holding 4 of the 9 samples
    out = tmp_path / "out.zarr"
    killed = tmp_path / "killed.zarr"
    shutil.copytree(ref, killed)
    for k in range(4, 9):
        shutil.rmtree(killed / sample_group(k))
    j = json.loads((killed / "zarr.json").read_text())
    j["attributes"].pop(WHITE)
    (killed / "zarr.json").write_text(json.dumps(j))
    dead_partial(killed, out)
    res = api_bake(toml, out, resume=True)
    assert res.reused_samples == 4 and open_store(out).attrs[WHITE] == want
    # add_samples: 1 x 1 x 3 -> 3 x 1 x 3, the old store without records
    small = tmp_path / "small.zarr"
    api_bake(scene_file(tmp_path, grid=(1, 1, 3), name="small.toml"), small)
    drop_records(small)
    api_bake(scene_file(tmp_path, grid=(3, 1, 3), name="small.toml"), small, add_samples=True)
    assert open_store(small).attrs[WHITE] == want == scanned(small)
    # compress: the white of the decoded rows, not of the source's
    for codec in ("f16", "q8", "cpca:4:2"):
        c = tmp_path / f"c-{codec.replace(':', '_')}.zarr"
        compress_store(ref, c, codec)
        got = open_store(c).attrs[WHITE]
        assert got == scanned(c) and got == pytest.approx(want, rel=0.05)


def test_white_of_a_distributed_bake(tmp_path):
    import distributed  # the dev extra installs it

    toml = scene_file(tmp_path, grid=(3, 1, 2))
    ref, out = tmp_path / "ref.zarr", tmp_path / "out.zarr"
    api_bake(toml, ref)
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=False, dashboard_address=":0") as cluster:
        api_bake(toml, out, scheduler=cluster.scheduler_address)
    assert open_store(out).attrs[WHITE] == open_store(ref).attrs[WHITE] == scanned(out)


def bake_peak(scene) -> tuple[int, list[int]]:
    """tracemalloc's peak over a bake of ``scene`` (the hierarchy built, every vertex kept, no store) and the traced
    memory after each finished sample."""
    after = []
    tracemalloc.start()
    try:
        bake(scene, None, sh_order=4, device="cpu", full=True, jobs=1,
             progress=lambda done, total: after.append(tracemalloc.get_traced_memory()[0]))
        return tracemalloc.get_traced_memory()[1], after
    finally:
        tracemalloc.stop()


def test_bake_memory_does_not_grow_with_the_samples():
    """8 vs 64 light samples: the peak of the bake's traced allocations within 10%, and what stays allocated after
    each sample flat: a sample's coefficients (~190 KB here) go once written, its statistics (< 1 KB) stay. On a
    busy machine the progress callback may see one sample's coefficients still on their way to the writer (the
    traced memory then swings by ~190 KB from one sample to the next), so the growth is read between the least
    values of two windows of 8 samples, 48 samples apart."""
    bake(spot_scene(grid=(1, 1, 1)), None, sh_order=4, device="cpu", hierarchy=False)  # kernels loaded first
    peak8, _ = bake_peak(spot_scene(grid=(2, 2, 2), floor=2))
    peak64, after = bake_peak(spot_scene(grid=(4, 4, 4), floor=2))
    assert len(after) == 64
    assert peak64 <= 1.1 * peak8, (peak8, peak64)
    assert min(after[-8:]) - min(after[8:16]) < 48 * 4096, after  # the statistics dicts only
