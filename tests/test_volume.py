"""Volumetric self-transfer (patent 4.3, docs/VOLUMES.md V-1..V-7): ray-marched attenuation against Beer-Lambert
and a float64 march, the scattering pass against numpy, energy across bounces, the store, the CLI, the GL marcher."""

import json

import re

import numpy as np
import pytest

from lodprt.cli.main import main
from lodprt.errors import LodprtError
from lodprt.model import sh
from lodprt.model.volume import Volume, load_volume, procedural_volume, sample_grid
from scipy.ndimage import map_coordinates
from lodprt.precompute.transfer import fibonacci_directions
from lodprt.precompute.volume import VolumeGrid, bake_volume, volume_transfer
from lodprt.runtime.volume_relight import open_volume, source_radiance



def trilinear(values, lo, hi, points):
    """The marches' oracle for V-1, independent of ``sample_grid``: scipy's linear interpolation at cell-centred
    coordinates, clamped to the edge, 0 outside the box: (..., C)."""
    v = np.asarray(values, np.float64)
    p = np.asarray(points, np.float64)
    u = (p - lo) / (np.asarray(hi, np.float64) - lo) * np.array(v.shape[:3]) - 0.5
    coords = u.reshape(-1, 3).T
    out = np.stack([map_coordinates(v[..., c], coords, order=1, mode="nearest") for c in range(v.shape[3])], -1)
    inside = np.all((p >= lo) & (p <= hi), axis=-1).reshape(-1)
    return (out * inside[:, None]).reshape(p.shape[:-1] + (v.shape[3],))

def box_exit(p, d, lo, hi):
    """float64 distance from p (inside) along unit d to the box boundary, for (N, 3) p and (R, 3) d: (N, R)."""
    with np.errstate(divide="ignore"):
        t_hi = (hi[None, None] - p[:, None]) / d[None]
        t_lo = (lo[None, None] - p[:, None]) / d[None]
    t = np.where(d[None] > 0, t_hi, np.where(d[None] < 0, t_lo, np.inf))
    return t.min(-1)


def slab(sigma=1.7, shape=(6, 3, 5), albedo=0.8):
    """A constant-density box, thin along y (a slab): lo (-1, 0, -1), hi (1, 0.4, 1)."""
    return Volume(np.full(shape, sigma, np.float32), np.array([-1.0, 0.0, -1.0]), np.array([1.0, 0.4, 1.0]), albedo, "slab")


@pytest.mark.warp_debug
def test_slab_transmittance_is_beer_lambert(device):
    """A constant slab attenuates every segment by exp(-sigma L), to the boundary by exp(-sigma D) (V-2, V-3)."""
    vol = slab()
    grid = VolumeGrid(vol, device=device)
    rng = np.random.default_rng(1)
    o = rng.uniform(vol.lo, vol.hi, size=(200, 3))
    d = rng.normal(size=(200, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    length = rng.uniform(0, 0.3, 200)
    inside = np.all((o + length[:, None] * d >= vol.lo) & (o + length[:, None] * d <= vol.hi), axis=1)
    a = grid.transmittance(o[inside], d[inside], length[inside])
    assert np.allclose(a, np.exp(-1.7 * length[inside]), rtol=2e-6)
    D = np.array([box_exit(o[i : i + 1], d[i : i + 1], vol.lo, vol.hi)[0, 0] for i in range(200)])
    assert np.allclose(grid.transmittance(o, d), np.exp(-1.7 * D), rtol=1e-5, atol=1e-7)


@pytest.mark.warp_debug
def test_slab_shadowed_transfer_is_beer_lambert_projection(device):
    """The shadowed pass of a constant slab equals albedo/(4 pi) sum_r w exp(-sigma D(p, s_r)) y_i(s_r) in float64,
    with D the exact distance to the slab's boundary (V-3)."""
    vol = slab()
    grid = VolumeGrid(vol, device=device)
    res = volume_transfer(grid, order=3, rays=96, bounces=0)
    dirs = fibonacci_directions(96).astype(np.float32).astype(np.float64)
    p = vol.centres().reshape(-1, 3)
    a = np.exp(-1.7 * box_exit(p, dirs, vol.lo, vol.hi))  # (N, R)
    ref = 0.8 / (4 * np.pi) * (4 * np.pi / 96) * a @ sh.basis(dirs, 3)
    got = res.transfer.reshape(-1, 3, 9)
    assert np.abs(got - ref[:, None, :]).max() < 2e-6 * 0.8
    assert 0 < res.energy[0] < 0.8  # a medium that attenuates scatters less than albedo x the sky


def test_trilinear_gradient_against_fine_float64_march():
    """Ray marching a random trilinear field matches a float64 march with 40x finer steps (V-1, V-2)."""
    rng = np.random.default_rng(2)
    vol = Volume(rng.uniform(0, 3, size=(5, 4, 6)).astype(np.float32), np.array([0.0, 0.0, 0.0]),
                 np.array([1.0, 0.8, 1.2]), 0.5, "random")
    grid = VolumeGrid(vol, device="cpu", step=0.01)
    o = rng.uniform(vol.lo, vol.hi, size=(40, 3))
    d = rng.normal(size=(40, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    D = np.array([box_exit(o[i : i + 1], d[i : i + 1], vol.lo, vol.hi)[0, 0] for i in range(40)])
    t = (np.arange(4000) + 0.5) / 4000
    x = o[:, None] + (t[None, :, None] * D[:, None, None]) * d[:, None]
    tau = (vol.sample(x) * (D[:, None] / 4000)).sum(1)
    assert np.allclose(grid.transmittance(o, d), np.exp(-tau), rtol=5e-4, atol=1e-6)


@pytest.mark.warp_debug
def test_scattering_pass_matches_numpy(device):
    """One gathering pass (V-4) equals the same steps in float64 numpy: weights T_before (1 - e^(-sigma dt))
    times the trilinear previous pass at each step's midpoint."""
    rng = np.random.default_rng(3)
    vol = Volume(rng.uniform(0, 2, size=(4, 3, 5)).astype(np.float32), np.array([0.0, 0.0, 0.0]),
                 np.array([1.0, 0.6, 1.0]), 0.7, "random")
    grid = VolumeGrid(vol, device=device)
    prev = rng.uniform(0, 1, size=vol.shape + (2,)).astype(np.float32)
    got = grid.bounce(prev, 12, seed=0, rotate=False)
    dirs = fibonacci_directions(12).astype(np.float32).astype(np.float64)
    p = vol.centres().reshape(-1, 3)
    ref = np.zeros((len(p), 2))
    for v in range(len(p)):
        for d in dirs:
            D = box_exit(p[v : v + 1], d[None], vol.lo, vol.hi)[0, 0]
            n = max(int(np.ceil(D / grid.step - 1e-3)), 1)  # kernels.volume.step_count
            dt = D / n
            x = p[v] + ((np.arange(n) + 0.5) * dt)[:, None] * d
            att = np.exp(-vol.sample(x) * dt)
            before = np.concatenate([[1.0], np.cumprod(att)[:-1]])
            ref[v] += (4 * np.pi / 12) * ((before * (1 - att))[:, None] * trilinear(prev, vol.lo, vol.hi, x)).sum(0)
    assert np.abs(got - ref).max() < 1e-5 * np.abs(ref).max()


def test_energy_never_grows_with_bounces():
    """Under a unit white sky each pass scatters at most albedo x the previous pass' largest radiance, every voxel
    (V-4 is an average times albedo), the density-weighted energy (V-5) falls each pass, and the sum stays below
    direct / (1 - albedo)."""
    vol = procedural_volume("cloud:10", albedo=0.75)
    res = volume_transfer(VolumeGrid(vol, device="cpu"), order=2, rays=24, bounces=4, threshold=0, keep_passes=True)
    white = np.sqrt(4 * np.pi)
    j = [white * p[..., 0] for p in res.passes]  # radiance scattered by each pass per voxel and channel
    assert j[0].max() <= 0.75 * (1 + 1e-6)
    for a, b in zip(j, j[1:]):
        assert b.max() <= 0.75 * a.max() * (1 + 1e-5)
        assert b.min() >= 0
    assert all(e1 < e0 for e0, e1 in zip(res.energy, res.energy[1:]))
    total = white * res.transfer[..., 0]
    assert total.max() <= j[0].max() / (1 - 0.75) + 1e-6


def test_volume_store_round_trip(tmp_path):
    """bake_volume writes a lodprt-volume store that reads back bit for bit, refuses to overwrite without
    overwrite=True and refuses other paths; the source radiance is the dot product (V-6)."""
    from lodprt.model.environment import procedural

    vol = procedural_volume("cloud:8")
    env = procedural("sky", resolution=16)
    out = tmp_path / "c.zarr"
    res = bake_volume(vol, out, sh_order=2, rays=8, bounces=1, environment=env, device="cpu")
    store = open_volume(out)
    assert np.array_equal(store.transfer(), res.transfer.transfer)
    assert np.array_equal(store.volume().density, vol.density)
    assert store.attrs["format"] == "lodprt-volume" and store.attrs["bounces"] == 1
    lighting = store.read("environment/coefficients")
    assert np.allclose(lighting, env.project(2))
    j = source_radiance(store.transfer(), lighting)
    assert np.allclose(j[1, 2, 3], (store.transfer()[1, 2, 3] * lighting).sum(-1), rtol=1e-5)
    with pytest.raises(LodprtError, match="already exists"):
        bake_volume(vol, out, sh_order=2, rays=8, bounces=0, device="cpu")
    (tmp_path / "x.txt").write_text("mine")
    with pytest.raises(LodprtError, match="not a lodprt volume store"):
        bake_volume(vol, tmp_path / "x.txt", sh_order=2, rays=8, bounces=0, device="cpu", overwrite=True)
    with pytest.raises(LodprtError, match="not a lodprt volume store"):
        open_volume(tmp_path / "x.txt")
    import zarr  # a bad value the store holds is named by the store, not by the file the bake read (cloud:8)

    zarr.open_group(str(out), mode="r+")["volume"].attrs["albedo"] = [2.0, 0.5, 0.5]
    with pytest.raises(LodprtError, match=rf"^{re.escape(str(out))}: volume: albedo must be one number or three"):
        open_volume(out).volume()


def test_load_volume_files_and_errors(tmp_path):
    """.npy with bounds, a TOML description with a relative .npy and albedo, and bad input named by file and field."""
    grid = np.random.default_rng(0).uniform(0, 1, (3, 4, 5)).astype(np.float32)
    np.save(tmp_path / "g.npy", grid)
    v = load_volume(tmp_path / "g.npy", bounds=(0, 0, 0, 1, 2, 3))
    assert v.shape == (3, 4, 5) and np.allclose(v.hi, [1, 2, 3]) and np.allclose(v.albedo, 0.9)
    (tmp_path / "v.toml").write_text('density = "g.npy"\nbounds = [0, 0, 0, 1, 1, 1]\nalbedo = [0.5, 0.6, 0.7]\n'
                                     'density_scale = 2.0\n')
    v = load_volume(tmp_path / "v.toml")
    assert np.allclose(v.density, 2 * grid) and np.allclose(v.albedo, [0.5, 0.6, 0.7])
    (tmp_path / "c.json").write_text(json.dumps({"density": "cloud:8", "albedo": 0.3}))
    assert load_volume(tmp_path / "c.json").shape == (8, 4, 8)
    with pytest.raises(LodprtError, match="bounds"):
        load_volume(tmp_path / "g.npy")
    np.save(tmp_path / "neg.npy", -grid)
    with pytest.raises(LodprtError, match="neg.npy.*negative"):
        load_volume(tmp_path / "neg.npy", bounds=(0, 0, 0, 1, 1, 1))
    holes = grid.astype(np.float32)
    holes[0, 1, 2] = np.nan
    np.save(tmp_path / "nan.npy", holes)
    with pytest.raises(LodprtError, match=r"nan.npy: density has 1 negative or non-finite voxel\(s\), the first at "
                                          r"\(0, 1, 2\) \(nan\)$"):  # the value as a number, not np.float32(nan)
        load_volume(tmp_path / "nan.npy", bounds=(0, 0, 0, 1, 1, 1))
    np.save(tmp_path / "flat.npy", grid[0])
    with pytest.raises(LodprtError, match="3-D grid"):
        load_volume(tmp_path / "flat.npy", bounds=(0, 0, 0, 1, 1, 1))
    (tmp_path / "bad.toml").write_text('density = "g.npy"\nbounds = [0, 0, 0, 1, 1, 1]\ncolour = 1\n')
    with pytest.raises(LodprtError, match="bad.toml.*colour"):
        load_volume(tmp_path / "bad.toml")
    with pytest.raises(LodprtError, match="albedo"):
        load_volume("cloud:8", albedo=1.5)
    with pytest.raises(LodprtError, match="max must exceed min"):
        load_volume(tmp_path / "g.npy", bounds=(0, 0, 0, 1, -1, 1))


def test_cli_bake_and_render_volume(tmp_path, gl, capsys):
    """lodprt bake-volume and render-volume run end to end; bad input exits 2 with a one-line message."""
    out = tmp_path / "c.zarr"
    assert main(["bake-volume", "cloud:8", "-o", str(out), "--rays", "8", "--bounces", "1", "--environment", "sky:16",
                 "--device", "cpu"]) == 0
    capsys.readouterr()
    assert main(["info", str(out)]) == 0  # info summarises it (it used to say: not a lodprt store)
    text = capsys.readouterr().out
    assert "lodprt volume store" in text and "bounces: 1" in text and "volume/density: 8 x 4 x 8 float32" in text, text
    png = tmp_path / "c.png"
    assert main(["render-volume", str(out), "--eye", "0", "0.8", "2.6", "--size", "64", "48", "-o", str(png)]) == 0
    import matplotlib.image

    img = matplotlib.image.imread(png)
    assert img.shape[:2] == (48, 64) and img[..., :3].max() > 0.5 and img[0, 0, :3].max() == 0
    assert main(["render-volume", str(out), "--eye", "0", "0.8", "2.6", "-o", str(png)]) == 2
    assert "already exists" in capsys.readouterr().err
    np.save(tmp_path / "g.npy", np.ones((2, 2, 2), np.float32))
    assert main(["bake-volume", str(tmp_path / "g.npy"), "-o", str(tmp_path / "g.zarr")]) == 2
    assert "bounds" in capsys.readouterr().err


def test_gl_march_matches_float64_march(gl):
    """The fragment shader's ray march (V-7) equals a float64 numpy march of the same camera rays."""
    from lodprt.display.volume_render import camera, march

    rng = np.random.default_rng(4)
    dens = rng.uniform(0, 4, size=(5, 4, 6)).astype(np.float32)
    src = rng.uniform(0, 1, size=(5, 4, 6, 3)).astype(np.float32)
    lo, hi = np.array([-0.5, -0.4, -0.6]), np.array([0.5, 0.4, 0.6])
    eye, size, step = np.array([0.4, 0.7, 1.9]), (24, 18), 0.05
    rgb, alpha = march(dens, src, lo, hi, eye=eye, size=size, step=step, background=(0.1, 0.2, 0.3))
    inv = np.linalg.inv(camera(eye, (lo + hi) / 2, (0, 1, 0), 40.0, size, lo, hi))
    ys, xs = np.mgrid[0:18, 0:24]
    ndc = np.stack([(xs + 0.5) / 24 * 2 - 1, 1 - (ys + 0.5) / 18 * 2, np.ones_like(xs, float), np.ones_like(xs, float)], -1)
    far = ndc @ inv.T
    d = far[..., :3] / far[..., 3:] - eye
    d /= np.linalg.norm(d, axis=-1, keepdims=True)
    ref = np.zeros((18, 24, 3))
    tr_all = np.ones((18, 24))
    for y in range(18):
        for x in range(24):
            with np.errstate(divide="ignore"):
                ta, tb = (lo - eye) / d[y, x], (hi - eye) / d[y, x]
            t0, t1 = max(np.minimum(ta, tb).max(), 0.0), np.maximum(ta, tb).min()
            if t1 <= t0:
                continue
            n = max(int(np.ceil((t1 - t0) / step - 1e-3)), 1)
            dt = (t1 - t0) / n
            pts = eye + (t0 + (np.arange(n) + 0.5) * dt)[:, None] * d[y, x]
            att = np.exp(-trilinear(dens[..., None], lo, hi, pts)[:, 0] * dt)
            before = np.concatenate([[1.0], np.cumprod(att)[:-1]])
            ref[y, x] = ((before * (1 - att))[:, None] * trilinear(src, lo, hi, pts)).sum(0)
            tr_all[y, x] = before[-1] * att[-1]
    ref += tr_all[..., None] * np.array([0.1, 0.2, 0.3])
    assert (alpha > 0.5).sum() > 50
    assert np.abs(rgb - ref).max() < 2e-5  # float32 in the shader (measured 7e-7)
    assert np.abs(alpha - (1 - tr_all)).max() < 2e-5


def test_sample_grid_matches_an_independent_trilinear():
    """V-1's sampler against scipy's linear interpolation (cell-centred, clamped to the edge, 0 outside)."""
    rng = np.random.default_rng(3)
    values = rng.random((4, 3, 5, 2))
    lo, hi = np.array([-1.0, 0.0, 2.0]), np.array([1.0, 0.6, 3.0])
    points = rng.uniform(lo - 0.2, hi + 0.2, (500, 3))
    np.testing.assert_allclose(sample_grid(values, lo, hi, points), trilinear(values, lo, hi, points), atol=1e-12)


def test_volume_inputs_and_picture_options_are_checked(tmp_path, capsys):
    """albedo 'red' (a ValueError) or true (read as 1) is refused; cloud:400 is refused before it is built (it took
    40 s and then failed on its voxel count); render-volume refuses --white 0 or nan, --fov 0, a negative
    --background and --rotate nan naming the option, before the store is read."""
    from lodprt.model.volume import check_albedo

    for bad in ("red", True, [0.1, "x", 0.2]):
        with pytest.raises(LodprtError, match="albedo must be one number or three"):
            check_albedo(bad, "p.toml")
    np.testing.assert_array_equal(check_albedo(0.5, "p"), [0.5, 0.5, 0.5])
    with pytest.raises(LodprtError, match=r"cloud:400: 32,000,000 voxels, more than the 16,777,216 .* \(N up to 322\)"):
        procedural_volume("cloud:400")
    missing = str(tmp_path / "none.zarr")
    for opts, msg in ((["--white", "0"], "--white 0: must be a positive radiance"),
                      (["--fov", "0"], "--fov 0: must lie strictly between 0 and 180"),
                      (["--background", "-1", "0", "0"], "--background -1 0 0: must be >= 0"),
                      (["--white", "nan"], "argument --white: 'nan' is not a finite number"),
                      (["--rotate", "nan"], "argument --rotate: 'nan' is not a finite number")):
        try:
            code = main(["render-volume", missing, "--eye", "0", "0.5", "3", "-o", str(tmp_path / "v.png"), *opts])
        except SystemExit as stop:  # argparse's own refusal
            code = stop.code
        assert code == 2 and msg in capsys.readouterr().err, opts


def test_bake_volume_refuses_a_step_of_endless_marching_and_bad_bounds(tmp_path, capsys):
    """bake-volume --step 1e-9 marched ~2e9 steps a ray without end: a step giving more than 2^20 steps across the
    box's diagonal is refused naming --step and the smallest step allowed, before any work; --bounds with max under
    min said 'bounds: bounds:' (the prefix twice), and now names --bounds."""
    from lodprt.precompute.volume import MAX_MARCH_STEPS, check_step

    out = tmp_path / "v.zarr"
    for opts, msg in ((["--step", "1e-9"], "--step 1e-09: 3e+09 march steps across the box's diagonal (3), more "
                                           "than 1,048,576 (2^20); give --step >= 2.86e-06"),
                      (["--step", "0"], "--step 0: must be a positive number"),
                      (["--bounds", "1", "1", "1", "0", "0", "0"], "error: --bounds: max must exceed min")):
        assert main(["bake-volume", "cloud:8", "--rays", "1", "--sh-order", "1", "-o", str(out), *opts]) == 2, opts
        err = capsys.readouterr().err
        assert msg in err and "bounds: bounds" not in err, err
    assert not out.exists()
    vol = procedural_volume("cloud:8")
    diagonal = float(np.linalg.norm(vol.hi - vol.lo))
    assert check_step(vol, diagonal / MAX_MARCH_STEPS * 1.001) == pytest.approx(diagonal / MAX_MARCH_STEPS * 1.001)
    with pytest.raises(LodprtError, match=r"^volume step 1e-09: .* more than 1,048,576"):
        VolumeGrid(vol, device="cpu", step=1e-9)
    with pytest.raises(LodprtError, match=r"g.npy: bounds: max must exceed min") as caught:
        np.save(tmp_path / "g.npy", np.ones((2, 2, 2), np.float32))
        load_volume(tmp_path / "g.npy", bounds=(1, 1, 1, 0, 0, 0))
    assert "bounds: bounds" not in str(caught.value)
