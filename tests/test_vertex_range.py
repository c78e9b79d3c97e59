"""Vertex-range tasks of a distributed bake (docs/DISTRIBUTED.md, "Vertex ranges"): a light sample split into dask
tasks of contiguous vertex ranges (uneven last range, a range of one vertex) gives the in-process store byte for
byte, full resolution and on the light cut, also resumed; each task computes only its range; bad values are refused
by name."""

import json
import subprocess
import time

import numpy as np
import pytest
import zarr

from lodprt.errors import LodprtError
from lodprt.model.scene import load_scene
from lodprt.precompute import bake as bake_module
from lodprt.precompute.baker import Baker
from lodprt.precompute.vertex_ranges import cut_rows, row_ranges

from lodprt.store.sample_groups import complete_samples
from lodprt.store.writer import OWNER_FILE

from test_interrupt import dead_identity
from test_resume import FAST, TIMING, api_bake, assert_same_store, lodprt, scene_file

distributed = pytest.importorskip("distributed", reason="the distributed extra (pip install 'lodprt[distributed]')")


@pytest.fixture(scope="module")
def cluster():
    """Two thread workers (processes=False, as tests/test_distributed.py): the tasks run in this process."""
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=False, dashboard_address=":0") as c:
        yield c


@pytest.fixture(scope="module")
def scene(tmp_path_factory):
    """spot on a small floor (about 3,100 vertices), 3 light samples: (scene file, its baked vertices)."""
    toml = scene_file(tmp_path_factory.mktemp("scene"), grid=(3, 1, 1))
    return toml, int(load_scene(str(toml)).referenced.sum())


@pytest.fixture
def watch(monkeypatch):
    """``watch()`` records from then on the (start, stop) of every vertex-range launch by kind (the number of rows
    of each shading launch), and a whole-sample launch fails the test; returns the record."""
    seen = {"rows": [], "visibility": [], "shade": []}

    def spy(kind, original):
        def wrapper(self, light, start, stop):
            seen[kind].append((start, stop))
            return original(self, light, start, stop)
        return wrapper

    def whole(*_args, **_kw):
        raise AssertionError("a vertex-range bake baked a whole sample")

    original_shade = Baker.shade_rows

    def shade(self, light, ids, states):
        seen["shade"].append(len(ids))
        return original_shade(self, light, ids, states)

    def install():
        monkeypatch.setattr(Baker, "sample_rows", spy("rows", Baker.sample_rows))
        monkeypatch.setattr(Baker, "visibility_rows", spy("visibility", Baker.visibility_rows))
        monkeypatch.setattr(Baker, "shade_rows", shade)
        monkeypatch.setattr(Baker, "sample", whole)
        monkeypatch.setattr(Baker, "sample_cut", whole)
        return seen

    return install


def assert_same_arrays(a, b):
    """Every array of the two stores: the same dtype, shape and bytes (``tobytes``); every group's and array's
    attributes equal but for the timing ones (tests/test_resume.py ``TIMING``). Returns the number of arrays."""
    ga, gb = zarr.open_group(str(a), mode="r"), zarr.open_group(str(b), mode="r")
    ma, mb = dict(ga.members(max_depth=None)), dict(gb.members(max_depth=None))
    assert sorted(ma) == sorted(mb)
    arrays = 0
    for name, x in [("", ga), *ma.items()]:
        y = gb if name == "" else mb[name]
        group = "samples" if name.startswith("samples/") else name
        allowed = TIMING.get(group, set()) if isinstance(x, zarr.Group) else set()
        strip = lambda attrs: {k: v for k, v in attrs.items() if k not in allowed}  # noqa: E731
        assert strip(dict(x.attrs)) == strip(dict(y.attrs)), f"{name or '/'}: attributes differ"
        if isinstance(x, zarr.Array):
            u, v = x[...], y[...]
            assert (u.dtype, u.shape, x.chunks) == (v.dtype, v.shape, y.chunks), name
            assert u.tobytes() == v.tobytes(), f"{name}: bytes differ"
            arrays += 1
    return arrays


def test_row_ranges_and_cut_rows():
    """ceil(rows / size) contiguous ranges covering every row once, the last one shorter; a cut's rows of a vertex
    range are the run of its ascending ids inside that range (empty when none)."""
    assert row_ranges(10, 4) == [(0, 4), (4, 8), (8, 10)]
    assert row_ranges(5, 4) == [(0, 4), (4, 5)] and row_ranges(4, 4) == [(0, 4)]
    for rows, size in [(3107, 1000), (3107, 3106), (7, 1), (1, 5)]:
        spans = row_ranges(rows, size)
        assert len(spans) == -(-rows // size) and all(0 < b - a <= size for a, b in spans)
        assert np.array_equal(np.concatenate([np.arange(a, b) for a, b in spans]), np.arange(rows))
    baked = np.array([0, 2, 3, 5, 8, 9, 11], np.int32)
    ids = np.array([2, 5, 9, 11], np.int32)
    assert [cut_rows(ids, baked, a, b) for a, b in row_ranges(7, 2)] == [(0, 1), (1, 2), (2, 3), (3, 4)]
    assert cut_rows(ids, baked, 2, 3) == (1, 1) and cut_rows(ids, baked, 3, 3) == (0, 0)


@pytest.mark.warp_debug
@pytest.mark.parametrize("mode", ["cut", "full"])
def test_vertex_ranges_give_the_in_process_store(mode, scene, cluster, watch, tmp_path):
    """Samples of R baked vertices split into ranges of 1,000 (an uneven last range) and of R - 1 (a last range of one
    vertex): each task launches only its range, and the store equals the in-process one byte for byte, every array
    (dtype, shape, bytes) and every attribute but the timings."""
    toml, rows = scene
    kw = {"full": True} if mode == "full" else {}
    ref = tmp_path / "ref.zarr"
    api_bake(toml, ref, **kw)
    ranges_seen = watch()
    for size in (1000, rows - 1):
        spans = row_ranges(rows, size)
        assert len(spans) >= 2 and spans[-1][1] - spans[-1][0] < size
        for kind in ranges_seen.values():
            kind.clear()
        out = tmp_path / f"ranges-{size}.zarr"
        res = api_bake(toml, out, scheduler=cluster.scheduler_address, vertex_range=size, **kw)
        assert res.reused_samples == 0 and len(res.samples) == 3
        if mode == "full":
            assert sorted(ranges_seen["rows"]) == sorted(spans * 3)
        else:
            assert sorted(ranges_seen["visibility"]) == sorted(spans * 3) and not ranges_seen["rows"]
            assert len(ranges_seen["shade"]) == 3 * len(spans) and max(ranges_seen["shade"]) <= size
        assert_same_store(ref, out)
        assert assert_same_arrays(ref, out) >= 3 * (2 if mode == "full" else 4)
    if mode == "cut":
        kept = [s["vertices_kept"] for s in res.samples]
        assert all(0 < k < rows for k in kept)  # a real light cut, shaded across the ranges


def test_vertex_ranges_resumed(scene, cluster, tmp_path, monkeypatch):
    """A vertex-range bake that fails while writing its last sample keeps the finished samples for --resume (the
    partial store records samples, not ranges); resumed with vertex ranges, it equals the in-process store."""
    toml, rows = scene
    ref = tmp_path / "ref.zarr"
    api_bake(toml, ref)
    out = tmp_path / "out.zarr"
    original = bake_module.SampleJob.write

    def failing(self, k, *args):
        if k == 2:
            end = time.monotonic() + 30  # the other worker finishes samples 0 and 1 meanwhile
            while len(complete_samples(self.partial, 3)) < 2 and time.monotonic() < end:
                time.sleep(0.01)
            raise OSError("lost the shared file system")  # what a cluster's storage failure raises
        return original(self, k, *args)

    monkeypatch.setattr(bake_module.SampleJob, "write", failing)
    with pytest.raises(LodprtError, match="--resume"):
        api_bake(toml, out, scheduler=cluster.scheduler_address, vertex_range=1000)
    monkeypatch.setattr(bake_module.SampleJob, "write", original)
    (partial,) = tmp_path.glob("out.zarr.partial-*")
    owner = dead_identity()  # as if this bake's process had been killed: --resume adopts only a dead writer's folder
    (partial / OWNER_FILE).write_text(json.dumps(owner))
    partial.rename(partial.with_name(f"out.zarr.partial-{owner['pid']}"))
    res = api_bake(toml, out, scheduler=cluster.scheduler_address, vertex_range=1000, resume=True)
    assert res.reused_samples == 2
    assert_same_store(ref, out)
    assert_same_arrays(ref, out)


def test_bad_vertex_range_is_refused_by_name(scene, tmp_path):
    """vertex_range 0, negative, fractional or bool, without a cluster, or with bounces: a LodprtError naming the
    option before any work; the CLI refuses --vertex-range 0 and lists the option in bake --help."""
    toml, _rows = scene
    out = tmp_path / "x.zarr"
    for bad in (0, -3, 2.5, True, "100"):
        with pytest.raises(LodprtError, match=r"vertex_range .*must be an integer >= 1"):
            api_bake(toml, out, workers=1, vertex_range=bad)
    with pytest.raises(LodprtError, match=r"vertex_range 100: splits light samples into dask tasks"):
        api_bake(toml, out, vertex_range=100)
    with pytest.raises(LodprtError, match=r"vertex_range 100: the interreflection passes"):
        api_bake(toml, out, workers=1, vertex_range=100, bounces=1)
    assert not out.exists() and not list(tmp_path.glob("x.zarr*"))
    r = subprocess.run(lodprt("bake", toml, "-o", out, "--workers", "1", "--vertex-range", "0"),
                       capture_output=True, text=True)
    assert r.returncode == 2 and "--vertex-range 0: must be >= 1" in r.stderr and "Traceback" not in r.stderr
    r = subprocess.run(lodprt("bake", "--help"), capture_output=True, text=True)
    assert r.returncode == 0 and "--vertex-range N" in r.stdout


def test_cli_workers_with_vertex_range(scene, tmp_path):
    """lodprt bake --workers 2 --vertex-range N (worker processes: the tasks and their results are pickled) gives
    the in-process store byte for byte, and -v says how the samples were split."""
    toml, rows = scene
    ref = tmp_path / "ref.zarr"
    api_bake(toml, ref)
    out = tmp_path / "out.zarr"
    r = subprocess.run(lodprt("-v", "bake", toml, "-o", out, *FAST, "--workers", "2", "--vertex-range", "1500"),
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    assert f"light samples of {rows} baked vertices: {-(-rows // 1500)} vertex-range tasks of at most 1500" in r.stderr
    assert_same_store(ref, out)
    assert_same_arrays(ref, out)
