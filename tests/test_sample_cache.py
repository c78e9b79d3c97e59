"""The run time's lazy light samples (``lodprt.runtime.samples.SampleCache``): a Runtime completes only the samples
its lights use, holds at most ``cache_bytes`` of them (never fewer than one frame needs), and gives the same
coefficients, radiance and view-cut errors as the stored samples completed one by one (``light_coefficients``)
however often slots are replaced."""

import numpy as np
import pytest

from lodprt.errors import LodprtError
from lodprt.runtime.camera import Camera
from lodprt.runtime.frames import light_coefficients
from lodprt.runtime.samples import SampleCache, default_white
from lodprt.runtime.session import Runtime
from lodprt.store.bake_store import open_store


@pytest.fixture(scope="module")
def store(bunny_bake):
    return open_store(bunny_bake)


def camera(rt):
    c = 0.5 * (rt.bounds[0] + rt.bounds[1])
    ext = float((rt.bounds[1] - rt.bounds[0]).max())
    return Camera(eye=tuple(c + ext * np.array([0.3, 0.5, 0.9])), target=tuple(c), width=320, height=240)


def light_path(store, n):
    """Lights wandering through the sampled box (each between samples: up to 8 in use)."""
    lo, hi = np.min(store.light_positions, 0), np.max(store.light_positions, 0)
    t = np.linspace(0.05, 0.95, n)
    return lo + (hi - lo) * np.stack([t, 0.5 + 0.3 * np.sin(7 * t), (7 * t) % 1.0], 1)


def test_opening_completes_only_the_samples_in_use(store):
    rt = Runtime(store, device="cpu", lod=False)
    assert rt.samples.completed == len(rt.used_samples) < store.num_samples
    assert rt.samples.nbytes <= max(rt.samples.slots, 1) * rt.samples.bytes_per_slot()


@pytest.mark.warp_debug
def test_small_cache_evicts_and_stays_exact(store):
    per = Runtime(store, device="cpu", lod=False).samples.bytes_per_slot()
    rt = Runtime(store, device="cpu", cache_bytes=2 * per)  # fewer slots than one frame may need: it grows to that
    rt.set_camera(camera(rt))
    big = Runtime(store, device="cpu")  # every sample fits
    big.set_camera(camera(big))
    for p in light_path(store, 8):
        rt.set_lights([p])
        big.set_lights([p])
        assert rt.samples.slots <= max(len(rt.used_samples), 2)
        want = light_coefficients(store, [p])[2]  # the stored samples completed one by one
        got = rt.coefficients()
        np.testing.assert_allclose(got, want, rtol=1e-4, atol=1e-6 * np.abs(want).max())
        np.testing.assert_array_equal(got, big.coefficients())
        f = rt.update()
        g = big.update()
        np.testing.assert_array_equal(f.vertex_ids, g.vertex_ids)  # the same errors, the same cut
        np.testing.assert_allclose(f.radiance, g.radiance, rtol=1e-6, atol=1e-7)
        nodes = np.arange(rt.h.num_vertices, rt.h.num_nodes, 7)
        np.testing.assert_array_equal(rt.node_errors(nodes).error, big.node_errors(nodes).error)
    assert rt.samples.completed > rt.samples.slots  # slots were replaced along the way


def test_two_lights_grow_the_cache_to_one_frame(store):
    rt = Runtime(store, device="cpu", lod=False, cache_bytes=0)
    lo, hi = np.min(store.light_positions, 0), np.max(store.light_positions, 0)
    lights = [lo + 0.3 * (hi - lo), lo + 0.8 * (hi - lo)]
    rt.set_lights(lights)
    assert rt.samples.slots == len(rt.used_samples) > 8 // 2
    np.testing.assert_allclose(rt.coefficients(), light_coefficients(store, lights)[2], rtol=1e-4, atol=1e-6)


def test_progress_reports_before_the_first_sample_and_reporting_chains_and_restores(store):
    """``progress`` hears (0, n) before the first of n completions and (i, n) after the i-th; within
    ``reporting(cb)`` both it and ``cb`` hear them, and afterwards ``progress`` is the same object again."""
    own, extra = [], []
    rt = Runtime(store, device="cpu", lod=False, progress=lambda d, t: own.append((d, t)))
    n = rt.samples.completed
    assert own == [(i, n) for i in range(n + 1)]  # the opening's completions
    held = rt.samples.progress
    own.clear()
    far = np.argmax(np.linalg.norm(store.light_positions - rt.light_positions[0], axis=1))
    with rt.samples.reporting(lambda d, t: extra.append((d, t))):
        rt.set_lights([store.light_positions[far]])
        done = rt.samples.completed - n
        rt.set_lights([store.light_positions[far]])  # held now: no report at all
    assert done >= 1 and own == extra == [(i, done) for i in range(done + 1)]
    assert rt.samples.progress is held
    with pytest.raises(RuntimeError), rt.samples.reporting(extra.append):
        raise RuntimeError("interrupted")
    assert rt.samples.progress is held


def test_default_white_reads_one_sample_at_a_time(store):
    w = default_white(store)
    dc = np.concatenate([np.abs(store.sample(k)[1][:, :, 0]).max(1) for k in range(store.num_samples)])
    assert w == pytest.approx(np.percentile(dc[dc > 0], 99) * 0.28209479177387814 * float(np.max(store.intensity)))


def test_bad_cache_size_is_refused(store):
    with pytest.raises(LodprtError, match="cache_bytes"):
        SampleCache(store, cache_bytes=-1)
    with pytest.raises(LodprtError, match="does not exist"):
        SampleCache(store).ensure([store.num_samples])


def test_run_time_memory_does_not_grow_with_the_samples(tmp_path):
    """Opening a store of 25 light samples allocates (tracemalloc) about what a store of 1 sample does: the run
    time completes the samples its light uses, not all of them."""
    import tracemalloc

    from lodprt.model.scene import load_scene
    from lodprt.precompute.bake import bake
    from test_resume import scene_file

    peaks, per = {}, 0
    for grid in ((1, 1, 1), (5, 1, 5)):
        toml = scene_file(tmp_path, grid=grid, name=f"scene{grid[0]}.toml")
        out = tmp_path / f"scene{grid[0]}.zarr"
        bake(load_scene(str(toml)), out, sh_order=8, device="cpu", threshold_deg=5.0)
        store = open_store(out)
        per = store.num_vertices * store.coefficients_per_vertex * 4  # one completed sample, float32
        tracemalloc.start()
        rt = Runtime(store, device="cpu", lod=False)
        peaks[grid] = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()
        assert rt.samples.completed <= 8
    assert peaks[(5, 1, 5)] - peaks[(1, 1, 1)] < 4 * per, (peaks, per)  # all 25 would add 24 x per


@pytest.mark.warp_debug
def test_direct_field_in_many_slices_equals_one_launch(store, monkeypatch):
    """The per-sample shadow rays and Phong SH run in slices of referenced rows on every core, each with its own
    buffers: slices of 97 rows give the bit-identical visibility, D_j V_j and M-2 residual of one launch."""
    from lodprt.runtime import direct_light

    direct = direct_light.DirectLight(store, "cpu")
    c = np.random.default_rng(1).normal(size=(store.num_vertices, direct.channels, direct.ncoef)).astype(np.float32)
    one = direct.direct_field(2), direct.split(2, c)
    monkeypatch.setattr(direct_light, "SLICE_ROWS", 97)
    many = direct.direct_field(2), direct.split(2, c)
    assert len(direct.referenced) > 4 * 97 and (one[0][1] != 0).any()
    # slices of consecutive rows (added in place), and with gaps (gathered) where the store has unreferenced
    # vertices between referenced ones (the full bunny's; the bounds-checked run's decimated bunny has none)
    ref = direct.referenced
    gaps = [ref[a:a + 97][-1] - ref[a] != len(ref[a:a + 97]) - 1 for a in range(0, len(ref), 97)]
    assert not all(gaps) and (any(gaps) or ref[-1] - ref[0] == len(ref) - 1)
    for a, b in zip(one, many):
        np.testing.assert_array_equal(a[0], b[0])
        np.testing.assert_array_equal(a[1], b[1])
    np.testing.assert_array_equal(one[1][1][direct.referenced], c[direct.referenced] - one[0][1][direct.referenced])


def test_direct_only_store_keeps_no_coefficients_and_the_same_bounds(store):
    """M-1 on a direct-only store reads no sample coefficients: the slots hold none and no sample is completed,
    yet the per-node bounds (S-2 detail, E-4's mean square) are exactly those made from the completed
    sample with D_j V_j written over its referenced vertices (the path that completes it)."""
    from lodprt.runtime import frame_error, node_bounds

    assert not int(store.attrs.get("bounces", 0) or 0)  # a direct-only store
    rt = Runtime(store, device="cpu", target_psnr=36)
    rt.set_lights(store.light_positions[[3, 5]])
    assert rt.samples.coeffs.shape[0] == 0 and rt.samples.coeffs.nbytes == 0
    C, n = rt.samples.C, rt.samples.n
    assert n > 1 and rt.samples.bytes_per_slot() < store.num_vertices * 4 * C * n / 4  # bounds only: no coefficients
    h, plan, white = rt.h, store.completion_plan(), rt.white
    levels, rings = node_bounds.height_levels(h), node_bounds.vertex_adjacency(rt.faces)
    direct = rt.lighting.direct
    for slot in rt.used_slots:
        k = int(rt.samples.slot_sample[slot])
        f = store.complete(k, dtype=np.float32)
        f[store.referenced] = direct.direct_field(k)[1][store.referenced]
        up = node_bounds.float16_up  # the cache keeps both rounded up to float16
        np.testing.assert_array_equal(rt.detail[:, slot], up(node_bounds.detail_bounds(h, f, white, plan, rings, levels)))
        np.testing.assert_array_equal(rt.samples.derived["detail_ms"][0][:, slot],
                                      up(node_bounds.detail_mean_square(h, f, white, plan, levels)))
    rt.set_camera(camera(rt))
    frame = rt.update()
    assert len(frame.triangles) and frame_error is not None
