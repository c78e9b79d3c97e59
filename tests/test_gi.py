"""Diffuse interreflection in the point-light bake (docs/GI.md, THEORY.md G-1..G-8): closed forms (a uniformly lit
sphere enclosure, the form factor of a square panel), the energy bound of every pass, light in direct shadow,
bounces 0 byte for byte, the light cut with indirect light against the full-resolution GI bake."""

from __future__ import annotations

import math

import numpy as np
import pytest
import zarr

from lodprt.errors import LodprtError
from lodprt.model.scene import Material, assemble_scene
from lodprt.precompute.bake import bake
from lodprt.precompute.baker import Baker
from lodprt.precompute.gi import GISettings, attach, cosine_fibonacci, vertex_areas

SQRT_4PI = math.sqrt(4 * math.pi)


def icosphere_inward(subdivisions: int = 2):
    import trimesh

    s = trimesh.creation.icosphere(subdivisions=subdivisions, radius=1.0)
    return np.asarray(s.vertices, np.float64), np.asarray(s.faces, np.int64)[:, ::-1]  # wound inward: normals in


def sphere_scene(kd: float, ks: float = 0.0, shininess: float = 4.0):
    """A closed unit sphere seen from inside, the light at its centre: every point gets E = 1 at normal incidence."""
    pos, faces = icosphere_inward()
    box = [-1e-3, -1e-3, -1e-3, 1e-3, 1e-3, 1e-3]
    return assemble_scene([("sphere", pos, faces, Material((kd,) * 3, ks, shininess))], None,
                          {"grid": [1, 1, 1], "box": box, "radius": 1e-3}, "lights", "sphere")


def grid(n: int, half: float, y: float, down: bool = False):
    """An n x n quad grid over [-half, half]^2 at height y, facing +y (or -y with ``down``)."""
    t = np.linspace(-half, half, n + 1)
    x, z = np.meshgrid(t, t, indexing="ij")
    pos = np.stack([x.ravel(), np.full(x.size, y), z.ravel()], 1)
    idx = np.arange((n + 1) ** 2).reshape(n + 1, n + 1)
    a, b, c, d = idx[:-1, :-1].ravel(), idx[1:, :-1].ravel(), idx[1:, 1:].ravel(), idx[:-1, 1:].ravel()
    faces = np.concatenate([np.stack([a, d, c], 1), np.stack([a, c, b], 1)])  # counter-clockwise seen from +y
    return pos, (faces[:, ::-1] if down else faces)


def box_over_plane():
    """A 20 x 20 plane at y=0 and a floating box (y 0.4..0.8) above its centre, the light high above: the plane
    under the box is in full shadow, the box's underside faces away from the light."""
    import trimesh

    plane = grid(20, 2.0, 0.0)
    box = trimesh.creation.box(extents=(0.8, 0.4, 0.8))
    bpos = np.asarray(box.vertices) + [0.0, 0.6, 0.0]
    white = Material((0.7, 0.7, 0.7), 0.0, 1.0)
    return assemble_scene([("plane", plane[0], plane[1], white), ("box", bpos, np.asarray(box.faces), white)], None,
                          {"grid": [1, 1, 1], "box": [-0.01, 3.0, -0.01, 0.01, 3.02, 0.01]}, "lights", "box")


def gi_baker(scene, settings, order: int = 4, tree=None):
    ids = np.flatnonzero(scene.referenced).astype(np.int32)
    baker = Baker(scene, order, "cpu", ids)
    attach(baker, scene, settings, tree)
    return baker


def test_cosine_fibonacci_is_cosine_weighted():
    d = cosine_fibonacci(4096)
    assert np.allclose(np.linalg.norm(d, axis=1), 1.0)
    assert (d[:, 2] > 0).all()
    # pdf cos/pi: E[cos] = 2/3, E[cos^2] = 1/2, E[x] = E[y] = 0
    assert d[:, 2].mean() == pytest.approx(2 / 3, abs=1e-4)
    assert (d[:, 2] ** 2).mean() == pytest.approx(0.5, abs=1e-4)
    assert abs(d[:, 0].mean()) < 1e-3 and abs(d[:, 1].mean()) < 1e-3
    with pytest.raises(LodprtError, match="gi rays"):
        cosine_fibonacci(0)


def test_settings_refuse_bad_values():
    for kw, field in [({"bounces": -1}, "bounces"), ({"bounces": 1.5}, "bounces"), ({"threshold": float("nan")},
                      "bounce_threshold"), ({"rays": 0}, "gi_rays"), ({"indirect_threshold_deg": -1.0},
                      "indirect_threshold_deg")]:
        with pytest.raises(LodprtError, match=field):
            GISettings(**kw)


@pytest.mark.warp_debug
def test_sphere_enclosure_converges_to_radiosity():
    """Uniform enclosure: every pass is exactly kd times the previous one, the sum L0 / (1 - kd) (G-1, G-2)."""
    kd = 0.6
    scene = sphere_scene(kd)
    baker = gi_baker(scene, GISettings(bounces=40, threshold=0.0, rays=32))
    light = scene.lights.positions[0]
    coeffs, visible = baker.sample(light)
    d = np.linalg.norm(scene.positions, axis=1)
    direct = kd * np.einsum("vi,vi->v", scene.normals, -scene.positions) / d**3  # kd E cos, E = 1 / d^2
    radiance = coeffs[:, 0, 0] / SQRT_4PI
    expected = direct.mean() / (1.0 - kd)  # B = E kd / (1 - kd): the radiosity of a uniform enclosure
    assert np.abs(radiance / expected - 1).max() < 5e-3
    energy = baker.gi.energy[tuple(float(x) for x in light)]
    ratios = np.array(energy[1:]) / np.array(energy[:-1])
    assert np.allclose(ratios, kd, rtol=5e-3)


def test_sphere_specular_of_indirect_light():
    """The y_0 coefficient of the Phong lobe of uniform incident light L: sqrt(4 pi) ks L / (n + 1) (G-4)."""
    kd, ks, n = 0.5, 0.3, 4.0
    scene = sphere_scene(kd, ks, n)
    one = gi_baker(scene, GISettings(bounces=1, threshold=0.0, rays=1024))
    zero = Baker(scene, 4, "cpu", np.flatnonzero(scene.referenced).astype(np.int32))
    light = scene.lights.positions[0]
    indirect = one.sample(light)[0] - zero.sample(light)[0]
    l_in = kd * np.einsum("vi,vi->v", scene.normals, -scene.positions).mean()  # bounce 0, incident on every point
    expected_y0 = SQRT_4PI * (kd * l_in + ks * l_in / (n + 1))
    assert np.allclose(indirect[:, 0, 0], expected_y0, rtol=5e-3)
    # every band against a float64 quadrature of (ks / pi) L integral over the hemisphere of the lobe about R
    from lodprt.model import sh

    dirs, w = sh.quadrature(48)
    lobes = sh.cosine_power_lobe(dirs, n, 4)  # (Q, 16): the lobe's coefficients about each direction
    up = (scene.normals @ dirs.T) > 0  # (V, Q) the hemisphere of each vertex
    spec = ks / math.pi * l_in * (up * w) @ lobes
    diffuse = np.zeros_like(spec)
    diffuse[:, 0] = SQRT_4PI * kd * l_in
    assert np.abs(spec[:, 1:]).max() > 0.1 * spec[:, 0].max()  # the lobe is not constant: higher bands exist
    # the 1/cos weights converge slowly near the rim: 3.4 % of y_0 at 1024 rays, 7 % at 256 (docs/GI.md)
    assert np.abs(indirect[:, 0, :] - (spec + diffuse)).max() < 0.05 * spec[:, 0].max()


def form_factor_square(a: float, h: float) -> float:
    """Form factor from a point to a parallel square of half-width a centred at height h (4 corner rectangles)."""
    x = y = a / h
    corner = (x / math.sqrt(1 + x * x) * math.atan(y / math.sqrt(1 + x * x))
              + y / math.sqrt(1 + y * y) * math.atan(x / math.sqrt(1 + y * y))) / (2 * math.pi)
    return 4 * corner


def test_panel_form_factor():
    """A small patch facing up under a square panel lit uniformly from far below (the patch itself faces away
    from the light): its radiance is kd_patch F L_panel, F the closed-form form factor (G-2)."""
    panel = grid(5, 1.0, 1.0, down=True)  # no panel vertex in the patch's shadow (x, z = 0)
    patch = grid(2, 0.005, 0.0)
    mat_panel, mat_patch = Material((0.5,) * 3, 0.0, 1.0), Material((0.8,) * 3, 0.0, 1.0)
    scene = assemble_scene([("panel", *panel, mat_panel), ("patch", *patch, mat_patch)], None,
                           {"grid": [1, 1, 1], "box": [-0.01, -5000.0, -0.01, 0.01, -4999.9, 0.01],
                            "falloff": "none"}, "lights", "panel")
    baker = gi_baker(scene, GISettings(bounces=1, threshold=0.0, rays=1024))
    light = scene.lights.positions[0]
    coeffs, visible = baker.sample(light)
    got = coeffs[:, 0, 0] / SQRT_4PI
    patch_ids = np.flatnonzero(scene.object_id == 1)
    to = light - scene.positions[patch_ids[0]]
    cos_panel = 1.0 / math.sqrt(1 + (to[0] ** 2 + to[2] ** 2) / to[1] ** 2)
    expected = 0.8 * form_factor_square(1.0, 1.0) * 0.5 * cos_panel
    assert np.allclose(got[patch_ids], expected, rtol=1e-2)


@pytest.mark.warp_debug
def test_energy_bound_and_shadowed_vertices(tmp_path):
    """Every pass carries at most kd_max times the previous one's power (G-8); vertices in full shadow and
    back-facing ones get light once bounces > 0 and none without."""
    scene = box_over_plane()
    direct = bake(scene, tmp_path / "b0.zarr", sh_order=2, device="cpu", hierarchy=False, jobs=1)
    gi = bake(scene, tmp_path / "b3.zarr", sh_order=2, device="cpu", hierarchy=False, jobs=1, bounces=3,
              bounce_threshold=0.0, gi_rays=64)
    assert direct.samples[0]["shadowed"] > 0 and direct.samples[0]["back_facing"] > 0
    root0, root3 = zarr.open_group(str(tmp_path / "b0.zarr"), mode="r"), zarr.open_group(str(tmp_path / "b3.zarr"),
                                                                                          mode="r")
    ids = root0["samples/00000/vertex_ids"][...]
    c0 = root0["samples/00000/coefficients"][...][:, 0, 0]
    c3 = root3["samples/00000/coefficients"][...][:, 0, 0]
    under = (np.abs(scene.positions[ids, 0]) < 0.3) & (np.abs(scene.positions[ids, 2]) < 0.3) & \
        (scene.positions[ids, 1] == 0.0)
    below = (scene.object_id[ids] == 1) & (scene.positions[ids, 1] < 0.5)  # the box's underside
    assert under.sum() >= 4 and below.sum() == 4
    assert (c0[under] == 0).all() and (c0[below] == 0).all()
    assert (c3[under] > 0.02 * c0.max()).all() and (c3[below] > 0.02 * c0.max()).all()
    energy = root3.attrs["bounce_energy"][0]
    assert len(energy) == 4 and root3.attrs["bounces"] == 3
    for prev, cur in zip(energy[:-1], energy[1:]):
        assert 0 < cur <= 0.7 * prev
    assert "bounces" not in root0.attrs  # a direct-only store is today's


def _arrays(path):
    root = zarr.open_group(str(path), mode="r")
    out = {}

    def walk(g, prefix):
        for name, item in g.members():
            if isinstance(item, zarr.Group):
                walk(item, f"{prefix}{name}/")
            else:
                out[f"{prefix}{name}"] = item[...]

    walk(root, "")
    return root, out


TIMINGS = {"bake_seconds", "load_seconds", "hierarchy_seconds", "seconds"}


@pytest.mark.parametrize("threshold", [None, 10.0])
def test_bounces_zero_is_todays_store(tmp_path, threshold):
    scene = box_over_plane()
    from lodprt.model.hierarchy_build import build_hierarchy

    tree = build_hierarchy(scene.positions, scene.faces, scene.normals)
    bake(scene, tmp_path / "a.zarr", sh_order=3, device="cpu", threshold_deg=threshold, tree=tree)
    bake(scene, tmp_path / "b.zarr", sh_order=3, device="cpu", threshold_deg=threshold, tree=tree, bounces=0,
         gi_rays=7, bounce_threshold=0.5, indirect_threshold_deg=3.0)
    ra, a = _arrays(tmp_path / "a.zarr")
    rb, b = _arrays(tmp_path / "b.zarr")
    assert a.keys() == b.keys()
    for name in a:
        assert a[name].dtype == b[name].dtype and a[name].tobytes() == b[name].tobytes(), name
    strip = lambda d: {k: v for k, v in d.items() if k not in TIMINGS}  # noqa: E731
    assert strip(dict(ra.attrs)) == strip(dict(rb.attrs))


@pytest.mark.warp_debug
def test_light_cut_with_indirect_light(tmp_path):
    """The GI light cut: gathers at fewer vertices, keeps the shadowed region's indirect light (no dark node
    there), and its completed radiance stays close to the full-resolution GI bake of the same settings."""
    from lodprt.model.hierarchy_build import build_hierarchy
    from lodprt.store.bake_store import open_store

    scene = box_over_plane()
    tree = build_hierarchy(scene.positions, scene.faces, scene.normals)
    kw = dict(sh_order=2, device="cpu", tree=tree, bounces=2, gi_rays=64, jobs=1)
    bake(scene, tmp_path / "full.zarr", threshold_deg=None, **kw)
    bake(scene, tmp_path / "cut.zarr", threshold_deg=1.0, indirect_threshold_deg=30.0, **kw)
    full, cut = open_store(tmp_path / "full.zarr"), open_store(tmp_path / "cut.zarr")
    ref = scene.referenced
    a, b = full.coefficients(0)[ref, 0, 0], cut.coefficients(0)[ref, 0, 0]
    rel = np.sqrt(np.mean((a - b) ** 2) / np.mean(a**2))
    assert rel < 0.08
    gathered = zarr.open_group(str(tmp_path / "cut.zarr"), mode="r").attrs["indirect_gather_vertices"]
    assert gathered < 0.8 * ref.sum()
    under = ref & (np.abs(scene.positions[:, 0]) < 0.3) & (np.abs(scene.positions[:, 2]) < 0.3) & \
        (scene.positions[:, 1] == 0.0)
    assert (cut.coefficients(0)[under, 0, 0] > 0).all()
    dark = zarr.open_group(str(tmp_path / "cut.zarr"), mode="r")["samples/00000/dark"][...]
    assert not dark.any()  # every node carries indirect light
    # the run time on the GI store (M-1 over the sample's residual, M-2: kernels.runtime.relight, then the direct
    # term; the scene has one light sample): the view cut's frame equals Runtime.radiance's numpy blend
    from lodprt.runtime.session import Runtime

    rt = Runtime(cut, device="cpu")
    rt.set_lights(cut.light_positions[:1])
    eye = (0.0, 0.25, 1.2)
    rt.set_camera(eye, target=(0.0, 0.1, 0.0), width=96, height=64)
    fr = rt.update()
    want = rt.radiance(eye)[fr.vertex_ids]
    assert float(np.abs(want).max()) > 0
    np.testing.assert_allclose(fr.radiance, want, atol=1e-4 * float(np.abs(want).max()), rtol=1e-3)


def test_vertex_areas_sum_to_the_surface():
    pos, faces = grid(3, 1.0, 0.0)
    assert vertex_areas(pos, faces).sum() == pytest.approx(4.0)


def test_commands_read_gi_stores(tmp_path, gl, capsys):
    """render, frames and compare on a GI light-cut store (the format is unchanged); the picture of the plane under
    the box is not black any more."""
    from lodprt.cli.main import main
    from lodprt.model.hierarchy_build import build_hierarchy

    scene = box_over_plane()
    tree = build_hierarchy(scene.positions, scene.faces, scene.normals)
    store = tmp_path / "gi.zarr"
    bake(scene, store, sh_order=2, device="cpu", tree=tree, threshold_deg=1.0, bounces=1, gi_rays=16, jobs=1)
    eye = ["--eye", "0", "0.25", "1.2", "--target", "0", "0.1", "0"]
    assert main(["render", str(store), "-o", str(tmp_path / "r.png"), "--size", "96", "64", *eye]) == 0
    assert main(["frames", str(store), "--frames", "2", "--size", "96", "64", "--json"]) == 0
    assert main(["compare", str(store), "--light", "0", "3", "0", "-o", str(tmp_path / "c.png"), "--size", "96", "64",
                 *eye]) == 0
    import imageio.v3 as iio

    img = iio.imread(tmp_path / "r.png")
    assert img.shape[:2] == (64, 96) and img.max() > 0


def test_cli_refuses_interreflection_options_it_would_drop_and_names_bad_values(tmp_path, capsys):
    """`bake --gi-rays 4` (or --indirect-tolerance, --indirect-threshold-deg, --bounce-threshold) without --bounces,
    and the indirect cut's options with --full or --no-hierarchy, were accepted and ignored (exit 0); a bad value
    was named as the library's field (gi_rays 0, bounces -1, bounce_threshold -1.0, indirect_tolerance 0.0 ... or
    None). Each is refused in one line naming the options, before the scene is read (exit 2); the defaults pass."""
    from lodprt.cli.main import main

    out = tmp_path / "g.zarr"
    cases = (
        (["--gi-rays", "4"], "error: --gi-rays without --bounces: with no --bounces B >= 1 the bake is direct light"),
        (["--indirect-tolerance", "0.05"], "error: --indirect-tolerance without --bounces"),
        (["--indirect-threshold-deg", "3"], "error: --indirect-threshold-deg without --bounces"),
        (["--bounce-threshold", "0.1", "--gi-rays", "64"], "error: --bounce-threshold, --gi-rays without --bounces"),
        (["--bounces", "1", "--full", "--indirect-tolerance", "0.05"],
         "error: --indirect-tolerance and --full: the indirect cut is a light cut's"),
        (["--bounces", "1", "--no-hierarchy", "--indirect-threshold-deg", "3"],
         "error: --indirect-threshold-deg and --no-hierarchy: the indirect cut is a light cut's"),
        (["--bounces", "1", "--indirect-threshold-deg", "3", "--indirect-tolerance", "0.05"],
         "error: --indirect-threshold-deg and --indirect-tolerance: the tolerance chooses where to gather instead"),
        (["--environment", "sky:8", "--gi-rays", "4"], "error: --gi-rays: point-light bake option; an environment"),
        (["--bounces", "1", "--gi-rays", "0"], "error: --gi-rays 0: must be an integer in 1..65536"),
        (["--bounces", "-1"], "error: --bounces -1: must be an integer in 0..64"),
        (["--bounces", "1", "--bounce-threshold", "-1"], "error: --bounce-threshold -1.0: must be finite and >= 0"),
        (["--bounces", "1", "--indirect-tolerance", "0"], "error: --indirect-tolerance 0: must lie in (0, 1] (a "
                                                          "relative RMS error of the indirect radiance, G-9)\n"),
    )
    for opts, msg in cases:
        assert main(["bake", str(tmp_path / "missing.toml"), "-o", str(out), "--device", "cpu", *opts]) == 2, opts
        err = capsys.readouterr().err
        assert msg in err and "missing.toml" not in err, (opts, err)
    assert not out.exists()
