"""Every kind of store a bake can make (1 or n^2 coefficients, 1 or 3 channels, light cut or full, with or without a
hierarchy, SH orders 1..8) through every radiance path and every command, on a scene of tens of thousands of
vertices (the bunny on a 40 x 40 floor), so that an index past an array's end lands outside the allocation (in the
bounds-checked run, where every access is checked, the bunny at a quarter of its faces: ``conftest.bunny_floor``).

The identities are checked per channel against references written from the arrays themselves (their widths, not
the settings the code uses): ``radiance --sample K`` == ``radiance --light <sample K>`` == ``full_frame(sample=K)``
== ``full_frame(lights=[sample K])`` == ``Runtime.radiance`` == ``light_radiance``; a diffuse full-resolution store
equals the closed form ``kd (N.L) I / d^2`` with Embree's visibility. The kernel tests are marked ``warp_debug``: the
bounds-checked subset (``python -m pytest --warp-debug -m warp_debug``, docs/TESTING.md) runs them with Warp's
bounds checks (the command tests add no kernel the others do not run).
"""

import dataclasses

import numpy as np
import pytest

from errors_reference import node_errors_reference

from lodprt.errors import LodprtError
from lodprt.model.scene import Material

GREY, RGB = (0.7, 0.7, 0.7), (0.9, 0.5, 0.2)
#: name -> (kd, ks, threshold_deg (None: full resolution), hierarchy, sh_order)
KINDS = {
    "grey-sh-cut": (GREY, 0.19, 30.0, True, 4),
    "grey-diffuse-cut": (GREY, 0.0, 30.0, True, 4),
    "rgb-sh-cut": (RGB, 0.3, 30.0, True, 3),
    "rgb-diffuse-cut": (RGB, 0.0, 30.0, True, 4),
    "rgb-diffuse-full": (RGB, 0.0, None, True, 4),
    "grey-sh-full-nohier": (GREY, 0.19, None, False, 2),
    "rgb-sh-order8": (RGB, 0.19, 30.0, True, 8),
}
EYES = [(0.05, 0.3, 0.45), (-0.4, 0.2, -0.1)]


def variant(scene, kd, ks):
    """``scene`` with every material replaced by (kd, ks, shininess 2) (same geometry, same hierarchy)."""
    mats = [Material(kd, ks, 2.0) for _ in scene.materials]
    return dataclasses.replace(scene, materials=mats)


@pytest.fixture(scope="module")
def kinds(bunny_floor, bunny_hierarchy, tmp_path_factory):
    """name -> (scene, store path) for every kind in KINDS."""
    from lodprt.precompute.bake import bake

    root = tmp_path_factory.mktemp("kinds")
    out = {}
    for name, (kd, ks, threshold, hier, order) in KINDS.items():
        scene = variant(bunny_floor, kd, ks)
        path = root / f"{name}.zarr"
        bake(scene, path, sh_order=order, device="cpu", threshold_deg=threshold, hierarchy=hier,
             tree=bunny_hierarchy if hier else None)
        out[name] = (scene, path)
    return out


def expected_width(kd, ks, order):
    """(coefficients per vertex, channels) a kind must store, from its material alone."""
    return (order * order if ks > 0 else 1), (1 if kd[0] == kd[1] == kd[2] else 3)


@pytest.mark.warp_debug
@pytest.mark.parametrize("name", list(KINDS))
def test_every_radiance_path_agrees(kinds, name):
    """For every store kind, the six radiance paths give the same (V, 3) radiance, channel by channel, and the
    store holds the coefficient width its material calls for (the light paths by the thesis interpolation, which
    reads the stored samples; the direct one, which is exact there, is checked against the closed form below)."""
    from lodprt.runtime.frames import full_frame
    from lodprt.runtime.camera import Camera
    from lodprt.runtime.frames import light_radiance
    from lodprt.runtime.session import Runtime
    from lodprt.store.bake_store import open_store

    kd, ks, _, hier, order = KINDS[name]
    _, path = kinds[name]
    store = open_store(path)
    ncoef, channels = expected_width(kd, ks, order)
    ids, coeffs = store.sample(0)
    assert coeffs.shape[1:] == (channels, ncoef) and store.coefficients_per_vertex == ncoef
    used = np.unique(store.faces)
    k = store.num_samples // 2
    light = store.light_positions[k]
    scale = None
    for eye in EYES:
        ref = store.radiance(k, eye)  # radiance --sample K
        scale = scale or float(np.abs(ref[used]).max())
        assert scale > 0 and ref.shape == (store.num_vertices, 3)
        paths = {"light_radiance": light_radiance(store, light[None], eye, interpolation="thesis")}
        cam = Camera(eye=eye, target=(0.0, 0.1, 0.0), width=64, height=48)
        by_sample = full_frame(store, cam, sample=k)
        by_light = full_frame(store, cam, lights=light[None], interpolation="thesis")
        for label, fr in (("full_frame(sample)", by_sample), ("full_frame(lights)", by_light)):
            assert fr.coefficients.shape == (len(fr.vertex_ids), 3, ncoef), label
            got = np.zeros_like(ref)
            got[fr.vertex_ids] = fr.radiance
            paths[label] = got
        if hier:
            rt = Runtime(store, device="cpu", interpolation="thesis")
            rt.set_lights(light[None])
            paths["Runtime.radiance"] = rt.radiance(eye)
            assert rt.coefficients(used[:5]).shape == (5, 3, ncoef)
        for label, got in paths.items():
            for c in range(3):
                np.testing.assert_allclose(got[used, c], ref[used, c], atol=2e-5 * scale, rtol=1e-4,
                                           err_msg=f"{name}: {label}, channel {c}")


@pytest.mark.warp_debug
@pytest.mark.parametrize("name", ["grey-diffuse-cut", "rgb-diffuse-cut", "rgb-diffuse-full"])
def test_diffuse_radiance_does_not_depend_on_the_eye(kinds, name):
    """A diffuse store's radiance is the same from two different eyes (T-7 with y_0 alone)."""
    from lodprt.store.bake_store import open_store

    store = open_store(kinds[name][1])
    a, b = (store.radiance(2, eye) for eye in EYES)
    np.testing.assert_allclose(a, b, rtol=1e-6, atol=1e-7)


@pytest.mark.warp_debug
def test_diffuse_full_store_equals_the_closed_form(kinds):
    """rgb-diffuse-full: every channel of every vertex is kd_c (N.L) I_c / max(d, radius)^2 where Embree sees the
    light, 0 where it does not (a handful of grazing rays may disagree between the two casters)."""
    from lodprt.precompute.baker import ray_offset
    from lodprt.precompute.reference import LIT, EmbreeCaster, visibility
    from lodprt.store.bake_store import open_store

    scene, path = kinds["rgb-diffuse-full"]
    store = open_store(path)
    caster = EmbreeCaster(scene)
    used = np.flatnonzero(scene.referenced)
    kd = np.array([m.kd for m in scene.materials])[scene.material_id[used]]  # (K, 3) from the scene, not the store
    intensity = np.asarray(scene.lights.intensity)
    for k in (0, store.num_samples - 1):
        light = scene.lights.positions[k]
        lit = visibility(caster, scene, light, ray_offset(scene), used) == LIT
        to = light[None] - scene.positions[used]
        d = np.linalg.norm(to, axis=1)
        ndotl = np.clip((scene.normals[used] * to).sum(1) / d, 0, None)
        expect = kd * (ndotl / np.maximum(d, scene.lights.radius) ** 2)[:, None] * intensity[None]
        expect[~lit] = 0
        got = store.radiance(k, EYES[0])[used]
        close = np.isclose(got, expect, rtol=1e-4, atol=1e-5 * expect.max()).all(1)
        assert close.mean() > 0.998, f"sample {k}: {np.count_nonzero(~close)} of {len(used)} vertices differ"


@pytest.mark.warp_debug
@pytest.mark.parametrize("order", range(1, 9))
def test_runtime_kernels_on_every_order(bunny_floor, bunny_hierarchy, tmp_path, order):
    """SH orders 1..8 (grey, specular: order^2 coefficients; order 1 is y_0 alone): the view-cut frame's
    relit radiance equals the float64 reference per vertex and the kernel's errors equal the reference's."""
    from lodprt.precompute.bake import bake
    from lodprt.runtime.session import Runtime
    from lodprt.store.bake_store import open_store

    scene = variant(bunny_floor, GREY, 0.19)
    scene = dataclasses.replace(scene, lights=dataclasses.replace(scene.lights, grid=(2, 1, 2)))
    path = tmp_path / "o.zarr"
    bake(scene, path, sh_order=order, device="cpu", threshold_deg=30.0, tree=bunny_hierarchy)
    rt = Runtime(open_store(path), device="cpu")
    assert rt.ncoef == order * order
    rt.set_camera(EYES[0], target=(0.0, 0.1, 0.0), width=200, height=150)
    fr = rt.update()
    ref = rt.radiance(EYES[0])[fr.vertex_ids]
    np.testing.assert_allclose(fr.radiance, ref, atol=1e-4 * float(np.abs(ref).max()), rtol=1e-3)
    nodes = np.arange(rt.h.num_vertices, rt.h.num_nodes, dtype=np.int32)[::7]
    got, want = rt.node_errors(nodes), node_errors_reference(rt, nodes)
    np.testing.assert_array_equal(got[0], want[0])
    np.testing.assert_allclose(got[3], want[3], atol=2e-3)


@pytest.mark.warp_debug
@pytest.mark.parametrize("interpolation", ["direct", "thesis"])
@pytest.mark.parametrize("name", ["grey-diffuse-cut", "rgb-diffuse-cut", "grey-sh-cut", "rgb-sh-cut",
                                  "rgb-diffuse-full"])
def test_view_cut_relighting_on_every_kind(kinds, name, interpolation):
    """The view-cut frame of a 1- or n^2-coefficient, 1- or 3-channel, cut or full store: relit radiance equals the
    float64 full-resolution reference at the active vertices, the kernel's e_lumi equals its float64 reference
    (which reads the boxes' own width), and the cut stays legal over a short orbit. ``direct`` relights a
    direct-only store by the direct term alone (``kernels.direct``); ``thesis`` blends the stored samples
    (``kernels.runtime.relight``), against ``Runtime.radiance``'s numpy blend."""
    from lodprt.runtime.session import Runtime
    from lodprt.store.bake_store import open_store

    rt = Runtime(open_store(kinds[name][1]), device="cpu", alpha=0.4, interpolation=interpolation)
    for a in np.linspace(0, 2 * np.pi, 5)[:-1]:
        eye = (0.6 * np.sin(a), 0.35, 0.6 * np.cos(a))
        rt.set_camera(eye, target=(0.0, 0.1, 0.0), width=200, height=150)
        fr = rt.update()
        rt.check()
        ref = rt.radiance(eye)[fr.vertex_ids]
        np.testing.assert_allclose(fr.radiance, ref, atol=1e-4 * float(np.abs(ref).max()), rtol=1e-3)
    nodes = np.arange(rt.h.num_vertices, rt.h.num_nodes, dtype=np.int32)[::5]
    got, want = rt.node_errors(nodes), node_errors_reference(rt, nodes)
    np.testing.assert_array_equal(got[0], want[0])
    np.testing.assert_allclose(got[3], want[3], atol=2e-3)


@pytest.mark.warp_debug
@pytest.mark.parametrize("name", list(KINDS))
def test_lights_between_samples_on_every_kind(kinds, name):
    """Every store kind under a light between samples, through every direct interpolation (M-1..M-4, the
    direct_light kernel on the cut and on the full mesh, with and without a hierarchy): ``light_coefficients``
    equals ``Runtime.coefficients`` and a frame's radiance equals its coefficients toward the eye; on a diffuse
    store the lit floor (Embree's visibility, off shadow edges) is as close to kd (N.L) I / d^2 between samples
    as on them (the light cut's completion error; float32 precision on a full-resolution store)."""
    from lodprt.runtime.camera import Camera
    from lodprt.runtime.frames import full_frame, light_coefficients
    from lodprt.runtime.session import Runtime
    from lodprt.store.bake_store import open_store, radiance_toward

    kd, ks, threshold, hier, _ = KINDS[name]
    scene, path = kinds[name]
    store = open_store(path)
    light = store.light_positions[[0, 1, 3, 4]].mean(0).astype(np.float64)[None]
    eye = EYES[0]
    cam = Camera(eye=eye, target=(0.0, 0.1, 0.0), width=64, height=48)
    for mode in ("direct", "direct-agree", "direct-blend"):
        _, _, free = light_coefficients(store, light, interpolation=mode, device="cpu")
        if ks == 0 and mode != "direct-blend":  # M-4 blends the samples' shadows: not exact between them
            err = closed_form_error(scene, store, light[0], free, kd)
            on = max(closed_form_error(scene, store, x, light_coefficients(store, x[None], interpolation=mode,
                                                                             device="cpu")[2], kd)
                     for x in store.light_positions[[0, 1, 3, 4]].astype(np.float64))
            assert err <= (2e-5 if threshold is None else 1.5 * on + 1e-4), (mode, err, on)
        if not hier:
            fr = full_frame(store, cam, lights=light, interpolation=mode)
            np.testing.assert_allclose(fr.coefficients, free[fr.vertex_ids], rtol=1e-5,
                                       atol=1e-6 * np.abs(free).max())
        else:
            rt = Runtime(store, device="cpu", interpolation=mode)
            rt.set_lights(light)
            rt.set_camera(cam)
            fr = rt.update()
            np.testing.assert_allclose(rt.coefficients(), free, rtol=1e-4, atol=1e-5 * np.abs(free).max())
            want = radiance_toward(fr.positions, fr.normals, fr.coefficients, eye, np.ones(3))
            np.testing.assert_allclose(fr.radiance, want, rtol=1e-4, atol=1e-5 * np.abs(want).max())


def closed_form_error(scene, store, light, coeffs, kd) -> float:
    """max over RGB and the floor's lit vertices off shadow edges (Embree) of |radiance - kd (N.L) I / d^2|, over
    the largest closed-form value."""
    from lodprt.kernels.visibility import LIT
    from lodprt.precompute import reference

    lit = reference.visibility(reference.EmbreeCaster(scene), scene, light, float(store.attrs["ray_offset"])) == LIT
    f = scene.faces
    edge = np.zeros(len(lit), bool)
    edge[f[lit[f].any(1) & ~lit[f].all(1)].ravel()] = True
    sel = (scene.object_id == scene.object_id.max()) & lit & ~edge
    to = light[None, :] - scene.positions[sel]
    d = np.linalg.norm(to, axis=1)
    closed = np.clip((scene.normals[sel] * to).sum(1) / d, 0, None) / np.maximum(d, scene.lights.radius) ** 2
    worst = 0.0
    for c in range(3):
        want = np.asarray(kd)[c] * store.intensity[c] * closed
        worst = max(worst, float(np.abs(coeffs[sel, c, 0] * 0.28209479177387814 - want).max() / want.max()))
    return worst


def cli(*argv):
    from lodprt.cli.main import main

    return main([str(a) for a in argv])


VIEW = ["--light", "0.05", "0.3", "0.1", "--eye", "0.05", "0.3", "0.45", "--target", "0", "0.1", "0",
        "--size", "96", "72"]


@pytest.mark.parametrize("name", list(KINDS))
def test_every_command_on_every_kind(kinds, name, tmp_path, capsys, gl):
    """info, radiance (--sample/--light), frames, render (png/npy, --full), compare, diff and turntable all run on
    every store kind (exit 0); render --full of a full-resolution bake equals the view cut where the cut is full."""
    path = kinds[name][1]
    _, _, threshold, hier, _ = KINDS[name]
    assert cli("info", path, "--json") == 0
    assert cli("radiance", path, "--sample", 1, "--eye", *EYES[0], "-o", tmp_path / "s.npy") == 0
    assert cli("radiance", path, "--light", 0.0, 0.3, 0.0, "--color", 1, 0.5, 0.2, "--eye", *EYES[1],
               "-o", tmp_path / "l.npy") == 0
    assert np.isfinite(np.load(tmp_path / "l.npy")).all()
    if hier:
        assert cli("frames", path, "--frames", 3, "--size", 96, 72, "--json") == 0
    assert cli("render", path, *VIEW, "-o", tmp_path / "f.png") == 0
    assert cli("render", path, *VIEW, "--full", "-o", tmp_path / "full.npy") == 0
    assert cli("render", path, *VIEW, "-o", tmp_path / "lod.npy", "--error-bound", 0) == 0
    if hier:  # at bound 0 every visible node refines: the view cut is the full mesh where it shows
        full, lod = np.load(tmp_path / "full.npy"), np.load(tmp_path / "lod.npy")
        assert np.abs(full - lod).mean() < 0.02 * full.max()
    assert cli("compare", path, *VIEW, "-o", tmp_path / "c.png") == 0
    assert cli("diff", path, "--sample", 1, "--eye", *EYES[0], "--size", 64, 48, "-o", tmp_path / "d.png") == 0
    assert cli("turntable", path, *VIEW, "--frames", 2, "-o", tmp_path / "t.gif") == 0
    capsys.readouterr()


def test_transfer_store_through_point_light_commands(tmp_path, capsys):
    """A transfer store (bake --environment) given to the point-light commands is a one-line error (exit 2), never
    a traceback; ``info`` summarises it."""
    import trimesh

    mesh = tmp_path / "ball.obj"
    trimesh.creation.icosphere(subdivisions=2).export(mesh)
    out = tmp_path / "ball.zarr"
    assert cli("bake", mesh, "--environment", "sky:16", "--sh-order", 2, "-o", out) == 0
    capsys.readouterr()
    assert cli("info", out) == 0 and "lodprt transfer store" in capsys.readouterr().out  # info summarises any kind
    for argv in (["radiance", out, "--sample", 0, "--eye", 0, 1, 3, "-o", tmp_path / "r.npy"],
                 ["frames", out, "--frames", 2], ["render", out, *VIEW, "-o", tmp_path / "f.png"],
                 ["compare", out, *VIEW, "-o", tmp_path / "c.png"],
                 ["diff", out, "--sample", 0, "--eye", 0, 1, 3, "-o", tmp_path / "d.png"]):
        assert cli(*argv) == 2, argv
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and "transfer" in err, (argv, err)


def test_huge_render_size_is_a_clear_error(kinds, tmp_path, capsys, gl):
    """render --size 100000 100000 names the context's size limit instead of a moderngl traceback."""
    path = kinds["grey-diffuse-cut"][1]
    view = VIEW[:-2] + ["100000", "100000"]
    assert cli("render", path, *view, "-o", tmp_path / "big.png") == 2
    err = capsys.readouterr().err
    assert "at most" in err and "GL_MAX_RENDERBUFFER_SIZE" in err and len(err.strip().splitlines()) == 1


def test_camera_straight_down_picks_another_up(kinds, tmp_path, gl):
    """A camera looking straight down with up = +y renders (another up vector is chosen) instead of failing."""
    from lodprt.runtime.camera import look_at

    m = look_at((0, 2, 0), (0, 0, 0), (0, 1, 0))
    assert np.isfinite(m).all() and np.allclose(m[:3, :3] @ m[:3, :3].T, np.eye(3))
    path = kinds["grey-diffuse-cut"][1]
    assert cli("render", path, "--light", 0, 0.3, 0, "--eye", 0, 1.0, 0, "--target", 0, 0, 0, "--size", 64, 48,
               "-o", tmp_path / "down.png") == 0
    with pytest.raises(LodprtError, match="coincide"):
        look_at((0, 1, 0), (0, 1, 0), (0, 1, 0))
