"""Lights between samples (M-1..M-4, docs/RUNTIME.md "Lights anywhere"): the default interpolation lights a point
light between samples as well as one on a sample. Oracles: the closed form ``kd (N.L) I E(d)``, the float64 Embree
bake of ``lodprt.precompute.reference`` at the actual light, and exact identities (a light on a sample gives the
sample back; several lights add; the thesis path is the T-12 sum of the completed samples)."""

import numpy as np
import pytest
import trimesh

from lodprt.errors import LodprtError
from test_view_cut import grid_plane

#: sample cell spacing of the scenes below: a 3 x 1 x 3 grid over a 0.6-wide box
BOX = (-0.3, 1.4, -0.3, 0.3, 1.6, 0.3)


def bake_grid(folder, objects: dict, *, ks=0.0, shininess=8.0, kd="0.6", threshold=5.0, order=4,
              falloff="inverse-square", bounces=0, box=BOX):
    """Bake ``objects`` (name -> trimesh) under a 3 x 1 x 3 light grid in ``box``: (scene, store)."""
    from lodprt.model.scene import load_scene
    from lodprt.precompute.bake import bake
    from lodprt.store.bake_store import open_store

    lines = []
    for name, mesh in objects.items():
        mesh.export(folder / f"{name}.obj")
        lines += ["[[object]]", f'mesh = "{name}.obj"', f"ks = {ks}", f"shininess = {shininess}", f"kd = {kd}"]
    lines += ["[lights]", "grid = [3, 1, 3]", f"box = {list(box)}", f'falloff = "{falloff}"']
    (folder / "s.toml").write_text("\n".join(lines) + "\n")
    scene = load_scene(folder / "s.toml")
    bake(scene, folder / "s.zarr", sh_order=order, device="cpu", threshold_deg=threshold, bounces=bounces,
         gi_rays=64)
    return scene, open_store(folder / "s.zarr")


def unshadowed(scene, light) -> np.ndarray:
    """The closed form kd (N.L) E(d) (unit intensity, grey kd of material 0) of every vertex (float64)."""
    to = light[None, :] - scene.positions
    d = np.linalg.norm(to, axis=1)
    cos = np.clip((scene.normals * to).sum(1) / d, 0, None)
    e = 1 / np.maximum(d, scene.lights.radius) ** 2 if scene.lights.falloff == "inverse-square" else 1.0
    return scene.materials[0].kd[0] * cos * e


def exact(scene, store, light, eye) -> np.ndarray:
    """Float64 Embree bake at ``light`` toward ``eye``, channel 0, unit intensity (lodprt.precompute.reference)."""
    from lodprt.precompute import reference
    from lodprt.store.bake_store import radiance_toward

    vis = reference.visibility(reference.EmbreeCaster(scene), scene, light, float(store.attrs["ray_offset"]))
    order = store.sh_order if store.coefficients_per_vertex > 1 else 1
    c = reference.phong_coefficients(scene, light, order, vis)
    return radiance_toward(scene.positions, scene.normals, c[:, None, :], eye, np.ones(3))[:, 0]


def runtime_radiance(store, light, eye, interpolation, **kw) -> np.ndarray:
    from lodprt.runtime.session import Runtime

    rt = Runtime(store, device=kw.pop("device", "cpu"), lod=False, interpolation=interpolation, **kw)
    rt.set_lights(np.asarray(light, np.float64).reshape(-1, 3), colors=np.ones(3))
    return rt.radiance(eye)[:, 0]


@pytest.fixture(scope="module")
def plane(tmp_path_factory):
    """A lit 61 x 61 plane, nothing over it, diffuse; light-cut and full-resolution bakes."""
    folder = tmp_path_factory.mktemp("plane")
    cut = bake_grid(folder, {"plane": grid_plane(61, 2.0)})
    full_folder = tmp_path_factory.mktemp("plane-full")
    return cut, bake_grid(full_folder, {"plane": grid_plane(61, 2.0)}, threshold=None)


@pytest.fixture(scope="module")
def box_shadow(tmp_path_factory):
    """A 0.3-wide box floating over a 121 x 121 plane (vertex spacing 1/60), diffuse, light-cut bake."""
    box = trimesh.creation.box((0.3, 0.1, 0.3))
    box.apply_translation((0.0, 0.4, 0.0))
    return bake_grid(tmp_path_factory.mktemp("box"), {"plane": grid_plane(121, 2.0), "box": box})


@pytest.mark.warp_debug
def test_unshadowed_plane_between_samples_equals_the_closed_form(plane, device):
    """Full-resolution store: a light between samples equals kd (N.L) I / d^2 to float32 precision (the thesis
    blend is off by percent); light-cut store: the error between samples is the completion error on a sample."""
    (scene_c, cut), (scene_f, full) = plane
    eye = np.array([0.2, 1.0, 1.5])
    between = np.array([0.1, 1.47, 0.1])  # halfway between four samples, below their layer
    want = unshadowed(scene_f, between)
    got = runtime_radiance(full, between, eye, "direct", device=device)
    np.testing.assert_allclose(got, want, rtol=2e-5, atol=1e-6 * want.max())
    thesis = runtime_radiance(full, between, eye, "thesis", device=device)
    assert np.abs(thesis - want).max() > 0.01 * want.max()  # the test tells the two apart
    # light cut: completion error, the same between samples as on them
    on_err = max(np.abs(runtime_radiance(cut, p, eye, "direct", device=device) - unshadowed(scene_c, p)).max()
                 / unshadowed(scene_c, p).max() for p in cut.light_positions.astype(np.float64))
    err = np.abs(runtime_radiance(cut, between, eye, "direct", device=device) - unshadowed(scene_c, between)).max()
    assert err / unshadowed(scene_c, between).max() <= 1.5 * on_err + 1e-5


@pytest.mark.warp_debug
def test_specular_between_samples_equals_the_float64_bake(tmp_path):
    """A glossy plane (Phong n = 8, SH order 4) under a light between samples: the run time's radiance toward the
    eye equals the float64 Embree bake at that light (same SH projection), for both direct modes with rays."""
    scene, store = bake_grid(tmp_path, {"plane": grid_plane(41, 2.0)}, ks=0.3, threshold=None)
    eye = np.array([0.3, 0.8, 1.2])
    light = np.array([-0.13, 1.55, 0.07])
    want = exact(scene, store, light, eye)
    for mode in ("direct", "direct-agree"):
        got = runtime_radiance(store, light, eye, mode)
        np.testing.assert_allclose(got, want, rtol=1e-4, atol=1e-5 * want.max(), err_msg=mode)


def shadow_profile(scene, store, light, rad, caster, offset):
    """(dark (V,) from ``rad``, exact shadow (V,), distance of each plane vertex to the exact shadow edge)."""
    from lodprt.kernels.visibility import SHADOWED
    from lodprt.precompute import reference
    from scipy.spatial import cKDTree

    plane = scene.object_id == 0
    vis = reference.visibility(caster, scene, light, offset)
    shadow = vis == SHADOWED
    u = unshadowed(scene, light)
    ratio = np.where(u > 0, rad / np.where(u > 0, u, 1), 0)
    e = scene.faces[np.isin(scene.faces, np.flatnonzero(plane)).all(1)]
    edges = np.r_[e[:, [0, 1]], e[:, [1, 2]], e[:, [2, 0]]]
    cross = edges[shadow[edges[:, 0]] != shadow[edges[:, 1]]].ravel()
    dist = cKDTree(scene.positions[np.unique(cross)]).query(scene.positions)[0]
    return ratio, shadow, np.where(plane, dist, np.inf)


@pytest.mark.parametrize("interpolation", ["direct", "direct-agree", "direct-blend", "thesis"])
def test_box_shadow_moves_with_the_light(box_shadow, interpolation):
    """The light crosses a sample cell in small steps: at every step one shadow (no vertex half dark farther than
    one vertex spacing from the exact edge: no ghost edge) whose edge lies within one spacing of where the
    geometry puts it. T-12 (thesis) and M-4 (direct-blend) cross-fade the samples' shadows and must fail this."""
    from lodprt.precompute import reference
    from lodprt.runtime.session import Runtime

    scene, store = box_shadow
    caster = reference.EmbreeCaster(scene)
    offset = float(store.attrs["ray_offset"])
    spacing = 2.0 / 120
    rt = Runtime(store, device="cpu", lod=False, interpolation=interpolation)
    eye = np.array([0.0, 2.0, 0.5])
    worst = 0.0
    for t in np.linspace(0.0, 1.0, 6):
        light = np.array([0.2 * t, 1.5, 0.1])  # from sample (0, 0) over the cell's middle to sample (0.2, 0)
        rt.set_lights(light[None], colors=np.ones(3))
        ratio, shadow, dist = shadow_profile(scene, store, light, rt.radiance(eye)[:, 0], caster, offset)
        near = dist <= 1.01 * spacing
        ghost = (ratio > 0.1) & (ratio < 0.9) & ~near & np.isfinite(dist)
        wrong = ((ratio < 0.5) != shadow) & ~near & np.isfinite(dist)
        worst = max(worst, ghost.sum() + wrong.sum())
        if interpolation in ("direct", "direct-agree"):
            assert not ghost.any(), f"light {light}: {ghost.sum()} half-dark vertices away from the edge"
            assert not wrong.any(), f"light {light}: {wrong.sum()} vertices on the wrong side of the edge"
    if interpolation in ("direct-blend", "thesis"):
        assert worst > 50  # the cross-fade of shadows (of the radiance or of the visibility): the oracle sees it


def test_a_light_on_a_sample_is_the_exact_direct_light(box_shadow):
    """A direct-only store, light on a sample: the direct path is the float64 Embree bake at that light (no
    completion error: R_j = 0), the thesis path the stored, completed sample, which the light cut left off it."""
    scene, store = box_shadow
    eye = np.array([0.1, 1.0, 1.0])
    for k in (0, 4, 7):
        p = store.light_positions[k].astype(np.float64)
        want = exact(scene, store, p, eye)
        np.testing.assert_allclose(runtime_radiance(store, p, eye, "direct"), want, rtol=1e-4,
                                   atol=1e-5 * want.max())
        stored = store.radiance(k, eye)[:, 0]
        np.testing.assert_allclose(runtime_radiance(store, p, eye, "thesis"), stored, rtol=1e-5,
                                   atol=1e-6 * np.abs(stored).max())
        assert np.abs(stored - want).max() > 1e-3 * want.max()  # the light cut's completion error


def test_several_coloured_lights_add(box_shadow):
    """Two coloured lights between samples: the coefficients are the sum of each light alone, channel by
    channel (M-1 is linear in the light's intensity)."""
    from lodprt.runtime.session import Runtime

    _, store = box_shadow
    rt = Runtime(store, device="cpu", lod=False)
    a, b = np.array([0.07, 1.52, -0.11]), np.array([-0.17, 1.45, 0.13])
    ca, cb = np.array([1.0, 0.5, 0.2]), np.array([0.1, 0.3, 0.9])
    rt.set_lights(np.stack([a, b]), colors=np.stack([ca, cb]))
    both = rt.coefficients()
    rt.set_lights(a[None], colors=ca)
    one = rt.coefficients()
    rt.set_lights(b[None], colors=cb)
    two = rt.coefficients()
    np.testing.assert_allclose(both, one + two, rtol=1e-5, atol=1e-6 * np.abs(both).max())
    assert np.abs(both[:, 0] - both[:, 2]).max() > 0  # the colours reach the channels


def test_light_coefficients_match_the_runtime(box_shadow):
    """``light_coefficients`` (no Runtime, any store) and ``Runtime.coefficients`` give the same numbers for a
    light between samples, both interpolations; the thesis path is exactly the T-12 sum of completed samples."""
    from lodprt.runtime.frames import light_coefficients
    from lodprt.runtime.lights import LightInterpolator
    from lodprt.runtime.session import Runtime

    _, store = box_shadow
    light = np.array([[0.11, 1.5, 0.09]])
    for mode in ("direct", "direct-agree", "direct-blend", "thesis"):
        rt = Runtime(store, device="cpu", lod=False, interpolation=mode)
        rt.set_lights(light)
        _, _, free = light_coefficients(store, light, interpolation=mode, device="cpu")
        np.testing.assert_allclose(free, rt.coefficients(), rtol=1e-4, atol=1e-6 * np.abs(free).max(),
                                   err_msg=mode)
    interp = LightInterpolator(store.light_positions, store.root["lights"].attrs["box"])
    W = interp.rgb_weights(light, store.intensity[None])
    want = np.zeros_like(free)
    for j in np.flatnonzero(np.abs(W).sum(1) > 0):
        want += store.coefficients(int(j)) * W[j][None, :, None]
    np.testing.assert_array_equal(free, want)  # thesis: bit for bit the T-12 sum


@pytest.mark.warp_debug
def test_gi_and_compressed_stores_go_through_the_direct_path(box_shadow, tmp_path):
    """A GI store (1 bounce): on a sample M-1 gives the sample back (R_j carries the indirect light), and between
    samples the indirect light survives in the plane's direct shadow. A q8-compressed direct-only store: the
    direct path is the exact direct light, without the codec's error."""
    from lodprt.store.bake_store import open_store
    from lodprt.store.compress import compress_store

    box = trimesh.creation.box((0.3, 0.1, 0.3))
    box.apply_translation((0.0, 0.4, 0.0))
    scene, gi = bake_grid(tmp_path, {"plane": grid_plane(41, 2.0), "box": box}, bounces=1)
    compress_store(box_shadow[1].path, tmp_path / "q8.zarr", codec="q8")
    eye = np.array([0.1, 1.0, 1.0])
    p = gi.light_positions[4].astype(np.float64)
    want = runtime_radiance(gi, p, eye, "thesis")
    np.testing.assert_allclose(runtime_radiance(gi, p, eye, "direct"), want, rtol=1e-4, atol=1e-5 * np.abs(want).max())
    q8 = open_store(tmp_path / "q8.zarr")
    between = np.array([0.13, 1.45, -0.07])
    want = exact(box_shadow[0], q8, between, eye)
    np.testing.assert_allclose(runtime_radiance(q8, between, eye, "direct"), want, rtol=1e-4, atol=1e-5 * want.max())
    light = np.array([0.1, 1.5, 0.1])
    got = runtime_radiance(gi, light, eye, "direct")
    direct = exact(scene, gi, light, eye)
    dark = (scene.object_id == 0) & (direct == 0) & (scene.positions[:, 1] > -1)
    assert dark.any() and np.median(got[dark]) > 0  # indirect light in the shadow


@pytest.mark.warp_debug
def test_kept_scratch_gives_what_fresh_scratch_gives(tmp_path, device):
    """``DirectLight.scratch`` keeps the direct term's SH scratch between calls (a full frame would otherwise page
    in two fresh arrays every frame): relighting row sets of growing, shrinking and changing sizes, with two
    glossy lights (the reflection basis is used) and a moving eye, gives bit for bit what a Runtime relighting each
    set first (fresh scratch) gives, and a smaller call reuses the memory a larger one made."""
    from lodprt.runtime.session import Runtime

    _, store = bake_grid(tmp_path, {"plane": grid_plane(41, 2.0)}, ks=0.3, threshold=None)
    lights = np.array([[-0.13, 1.55, 0.07], [0.2, 1.45, -0.1]])
    rng = np.random.default_rng(7)
    kept = Runtime(store, device=device, lod=False)
    kept.set_lights(lights)
    sets = [np.arange(store.num_vertices), np.sort(rng.choice(store.num_vertices, 300, replace=False)),
            np.arange(17), np.sort(rng.choice(store.num_vertices, 1200, replace=False))]
    for k, ids in enumerate(sets):
        eye = np.array([0.3 + 0.1 * k, 0.8, 1.2])
        kept.set_camera(eye, np.zeros(3))
        fresh = Runtime(store, device=device, lod=False)
        fresh.set_lights(lights)
        fresh.set_camera(eye, np.zeros(3))
        for got, want in zip(kept.relit(ids), fresh.relit(ids)):
            np.testing.assert_array_equal(got, want, err_msg=f"set {k}")
        assert np.abs(want).max() > 0
    direct = kept.lighting.direct
    big = direct.scratch(store.num_vertices, store.coefficients_per_vertex)
    small = direct.scratch(5, store.coefficients_per_vertex)
    assert small[0].shape == (5, store.coefficients_per_vertex) and small[0].ptr == big[0].ptr
    given = small[1]  # a given eye basis is the second array, and the first is still the kept one
    again = direct.scratch(5, store.coefficients_per_vertex, eye_basis=given)
    assert again[1] is given and again[0].ptr == big[0].ptr and big[1].ptr != big[0].ptr


def test_unknown_interpolation_is_a_clear_error(box_shadow):
    from lodprt.runtime.frames import light_coefficients
    from lodprt.runtime.session import Runtime

    with pytest.raises(LodprtError, match="interpolation 'linear': choose one of direct"):
        Runtime(box_shadow[1], device="cpu", interpolation="linear")
    with pytest.raises(LodprtError, match="interpolation"):
        light_coefficients(box_shadow[1], [(0, 1.5, 0)], interpolation="nearest")


@pytest.mark.parametrize("interpolation", ["direct", "thesis"])
def test_interpolation_flag_on_every_point_light_command(box_shadow, tmp_path, gl, interpolation):
    """``--interpolation`` on radiance, render, frames, compare, turntable and export: every command takes it and
    runs; radiance writes the API's numbers bit for bit; render --full writes a lit linear image."""
    from lodprt.cli.main import main
    from lodprt.runtime.frames import light_radiance

    _, store = box_shadow
    light, eye = ["0.11", "1.5", "0.09"], ["0.1", "1.0", "1.0"]
    view = ["--light", *light, "--eye", *eye, "--size", "64", "48", "--interpolation", interpolation]
    assert main(["radiance", str(store.path), "--light", *light, "--eye", *eye, "--interpolation", interpolation,
                 "-o", str(tmp_path / "r.npy")]) == 0
    want = light_radiance(store, [[0.11, 1.5, 0.09]], [0.1, 1.0, 1.0], interpolation=interpolation)
    np.testing.assert_array_equal(np.load(tmp_path / "r.npy"), want)
    assert main(["render", str(store.path), *view, "--full", "-o", str(tmp_path / "f.npy")]) == 0
    for argv in (["render", *view, "-o", tmp_path / "f.png"], ["compare", *view, "-o", tmp_path / "c.png"],
                 ["turntable", *view, "--frames", "2", "-o", tmp_path / "t"],
                 ["export", "--light", *light, "--eye", *eye, "--interpolation", interpolation, "-o", tmp_path / "e.glb"],
                 ["frames", "--frames", "3", "--interpolation", interpolation, "--json"]):
        assert main([str(argv[0]), str(store.path), *map(str, argv[1:])]) == 0, argv[0]
    img = np.load(tmp_path / "f.npy")
    assert img.shape == (48, 64, 3) and img.max() > 0


def test_light_colours_past_the_bakes_intensity_limit_are_refused():
    """A colour of 1e39 (past float32) or 1e13 (past the bake's intensity limit, 1e12) is refused naming the colours
    (1e39 drew NaN pixels); 1e12 is accepted."""
    from lodprt.errors import LodprtError
    from lodprt.runtime.lights import check_lights

    for big in (1e39, 1e13):
        with pytest.raises(LodprtError, match=r"light colors: each RGB intensity at most 1e\+12"):
            check_lights([(0, 1, 0)], [(big, 1, 1)], (1, 1, 1))
    assert check_lights([(0, 1, 0)], [(1e12, 1, 1)], (1, 1, 1))[1].max() == 1e12
