"""Distant-light transfer kernels (unshadowed, shadowed, interreflected, glossy) against closed forms and Embree,
the transfer store, and run-time relighting under a rotating environment."""

import json

import numpy as np
import pytest

from lodprt.model import environment as E
from lodprt.model import irradiance as I
from lodprt.model import sh
from lodprt.runtime import environment_relight as relight
from lodprt.precompute import transfer as T
from lodprt.errors import LodprtError
from lodprt.model.scene import Material, assemble_scene, vertex_normals
from lodprt.store.transfer_store import complete_transfer


def icosphere(subdivisions=2, radius=1.0, centre=(0, 0, 0)):
    import trimesh

    m = trimesh.creation.icosphere(subdivisions=subdivisions, radius=radius)
    return np.asarray(m.vertices) + centre, np.asarray(m.faces)


def grid(n, size, y, *, up=True):
    """(n x n) vertex square of side 2 size at height y, triangles facing +y (or -y)."""
    c = np.linspace(-size, size, n)
    x, z = np.meshgrid(c, c, indexing="ij")
    pos = np.stack([x.ravel(), np.full(n * n, y), z.ravel()], 1)
    i = np.arange(n - 1)[:, None] * n + np.arange(n - 1)[None, :]
    a, b, c2, d = i.ravel(), i.ravel() + n, i.ravel() + 1, i.ravel() + n + 1
    faces = np.concatenate([np.stack([a, c2, b], 1), np.stack([b, c2, d], 1)])
    if vertex_normals(pos, faces)[0, 1] < 0:
        faces = faces[:, ::-1]
    if not up:
        faces = faces[:, ::-1]
    return pos, faces


def plane_under_occluder():
    """A 9 x 9 plane at y = 0 and a 0.8 x 0.8 square occluder at y = 0.5 facing down."""
    p1, f1 = grid(9, 1.0, 0.0)
    p2, f2 = grid(3, 0.4, 0.5, up=False)
    pos = np.vstack([p1, p2])
    faces = np.vstack([f1, f2 + len(p1)])
    return pos, faces, vertex_normals(pos, faces)


def embree_shadowed(pos, faces, normals, dirs, offset, order):
    """Independent float64 oracle: the same quadrature with Embree occlusion rays (embreex)."""
    from embreex import rtcore_scene as rtcs
    from embreex.mesh_construction import TriangleMesh

    scene = rtcs.EmbreeScene()
    TriangleMesh(scene, pos[faces].astype(np.float32))
    y = sh.basis(dirs, order)
    out = np.zeros((len(pos), order * order))
    w = 4 * np.pi / len(dirs)
    for v in range(len(pos)):
        c = dirs @ normals[v]
        up = c > 0
        o = np.repeat((pos[v] + offset * normals[v])[None], up.sum(), 0)
        hit = np.asarray(scene.run(o.astype(np.float32), dirs[up].astype(np.float32), query="OCCLUDED")) != -1
        out[v] = (w * c[up][~hit]) @ y[up][~hit]
    return out


def test_fibonacci_set_is_unit_and_balanced():
    """The spherical Fibonacci set is unit length and integrates y_1..y_3 bands to ~0 (well distributed)."""
    d = T.fibonacci_directions(2048)
    assert np.allclose(np.linalg.norm(d, axis=1), 1)
    q = sh.basis(d, 4).sum(0) * 4 * np.pi / len(d)
    assert abs(q[0] - np.sqrt(4 * np.pi)) < 1e-12 and np.abs(q[1:]).max() < 2e-3
    with pytest.raises(LodprtError):
        T.fibonacci_directions(0)


@pytest.mark.warp_debug
def test_unshadowed_closed_form_kernel_matches_float64(device):
    """The unshadowed kernel (zonal cosine lobe rotated to n) equals sh.cosine_power_lobe to float32 precision."""
    pos, faces = icosphere(1)
    n = vertex_normals(pos, faces)
    g = T.Geometry.from_arrays(pos, faces, n, device=device)
    got = T.unshadowed_transfer_closed_form(g, order=5)
    assert np.abs(got - sh.cosine_power_lobe(n, 1.0, 5)).max() < 2e-6


@pytest.mark.parametrize("rotate", [False, True])
def test_convex_sphere_shadowed_transfer_equals_cosine_lobe(device, rotate):
    """On a convex sphere nothing blocks the upper hemisphere: ray-traced shadowed transfer = closed-form cosine lobe."""
    pos, faces = icosphere(2)
    n = vertex_normals(pos, faces)
    g = T.Geometry.from_arrays(pos, faces, n, device=device)
    got = T.geometric_transfer(g, order=3, rays=4096, shadowed=True, rotate=rotate)
    ref = sh.cosine_power_lobe(n, 1.0, 3)
    assert np.abs(got - ref).max() < 3e-3 * np.abs(ref).max()


@pytest.mark.warp_debug
def test_shadowed_plane_under_occluder_matches_embree(device):
    """Shadowed transfer of a plane under a square occluder equals the same quadrature with Embree rays (float64)."""
    pytest.importorskip("embreex")
    pos, faces, normals = plane_under_occluder()
    g = T.Geometry.from_arrays(pos, faces, normals, device=device)
    rays = 512
    got = T.geometric_transfer(g, order=3, rays=rays)
    dirs = T.fibonacci_directions(rays).astype(np.float32).astype(np.float64)
    ref = embree_shadowed(pos, faces, normals, dirs, g.offset, 3)
    w = 4 * np.pi / rays
    # a grazing ray may go either way in float32 vs Embree: allow two rays' worth per vertex
    assert np.abs(got - ref).max() < 2 * w * 0.5 + 1e-4
    assert np.linalg.norm(got - ref) < 1e-3 * np.linalg.norm(ref)
    unshadowed = sh.cosine_power_lobe(normals, 1.0, 3)
    centre = np.argmin(np.linalg.norm(pos[:81] - [0, 0, 0], axis=1))
    assert got[centre, 0] < 0.6 * unshadowed[centre, 0]  # the occluder does shadow the plane's centre


def test_threaded_launches_give_the_same_transfer(device):
    """Launching vertex ranges from 1 or 3 threads gives bit-identical interreflected transfer and glossy matrices."""
    pos, faces, normals = plane_under_occluder()
    g = T.Geometry.from_arrays(pos, faces, normals, 0.5, device=device)
    a = T.diffuse_transfer(g, order=2, mode="interreflected", rays=64, bounces=1, jobs=1).transfer
    b = T.diffuse_transfer(g, order=2, mode="interreflected", rays=64, bounces=1, jobs=3).transfer
    assert np.array_equal(a, b)
    ga = T.glossy_transfer(g, np.arange(20), order=2, rays=64, jobs=1)
    gb = T.glossy_transfer(g, np.arange(20), order=2, rays=64, jobs=3)
    assert np.array_equal(ga, gb)


@pytest.mark.warp_debug
def test_closest_hit_barycentrics_reconstruct_the_hit_point(device):
    """The bounce kernel's barycentric weights (u, v, 1-u-v) of the hit triangle's vertices give the hit point."""
    pos, faces, normals = plane_under_occluder()
    g = T.Geometry.from_arrays(pos, faces, normals, device=device)
    rng = np.random.default_rng(2)
    o = np.column_stack([rng.uniform(-0.9, 0.9, 200), np.full(200, 2.0), rng.uniform(-0.9, 0.9, 200)])
    d = np.tile([0.0, -1.0, 0.0], (200, 1))
    face, bary = T.closest_hits(g, o, d)
    assert (face >= 0).all()
    p = np.einsum("nk,nkd->nd", bary, pos[faces[face]])
    expect_y = np.where((np.abs(o[:, 0]) < 0.4) & (np.abs(o[:, 2]) < 0.4), 0.5, 0.0)
    assert np.allclose(p[:, [0, 2]], o[:, [0, 2]], atol=1e-5) and np.allclose(p[:, 1], expect_y, atol=1e-5)


def open_box():
    """Floor and three walls of a unit box, facing inward (a concave scene that interreflects)."""
    parts = []
    f, ff = grid(7, 1.0, -1.0)  # floor facing +y
    parts.append((f, ff))
    for rot in ([[0, 1, 0], [-1, 0, 0], [0, 0, 1]], [[0, -1, 0], [1, 0, 0], [0, 0, 1]], [[1, 0, 0], [0, 0, 1], [0, -1, 0]]):
        R = np.array(rot, float)
        parts.append((f @ R.T, ff))
    pos, faces, off = [], [], 0
    for p, fc in parts:
        pos.append(p)
        faces.append(fc + off)
        off += len(p)
    pos, faces = np.vstack(pos), np.vstack(faces)
    n = vertex_normals(pos, faces)
    inward = (n * -pos).sum(1) > 0
    assert inward.mean() > 0.9
    return pos, faces, n


@pytest.mark.warp_debug
def test_interreflection_adds_energy_and_converges(device):
    """In an open box (kd 0.7) each bounce is at most kd times the last; the total grows but stays below direct/(1-kd)."""
    pos, faces, n = open_box()
    kd = 0.7
    g = T.Geometry.from_arrays(pos, faces, n, kd, device=device)
    res = T.diffuse_transfer(g, order=3, mode="interreflected", rays=256, bounces=6, threshold=1e-4, keep_passes=True)
    e = res.energy
    assert len(e) == 7 and e[1] > 0.02 * e[0]
    for a, b in zip(e, e[1:]):
        assert 0 < b < a and b <= kd * a * 1.05
    assert sum(e) <= e[0] / (1 - kd) * 1.01
    direct = res.passes[0]
    assert (res.transfer[:, :, 0] >= direct[:, :, 0] - 1e-7).all()
    assert res.transfer[:, :, 0].sum() > 1.05 * direct[:, :, 0].sum()


def test_bounce_stops_at_the_energy_threshold(device):
    """A loose threshold stops after the first pass whose energy falls below threshold x direct."""
    pos, faces, n = open_box()
    g = T.Geometry.from_arrays(pos, faces, n, 0.5, device=device)
    res = T.diffuse_transfer(g, order=2, mode="interreflected", rays=64, bounces=10, threshold=0.05)
    assert res.energy[-1] < 0.05 * res.energy[0] and all(x >= 0.05 * res.energy[0] for x in res.energy[1:-1])
    assert len(res.energy) < 11


def test_first_bounce_matches_embree_reference(device):
    """One bounce pass equals a float64 numpy pass on the same rays with Embree closest hits and barycentrics."""
    pytest.importorskip("embreex")
    from embreex import rtcore_scene as rtcs
    from embreex.mesh_construction import TriangleMesh

    pos, faces, n = open_box()
    kd = 0.6
    g = T.Geometry.from_arrays(pos, faces, n, kd, device=device)
    rays, order = 128, 2
    res = T.diffuse_transfer(g, order=order, mode="interreflected", rays=rays, bounces=1, threshold=0, keep_passes=True)
    direct, bounce = res.passes[0].astype(np.float64), res.passes[1]
    scene = rtcs.EmbreeScene()
    TriangleMesh(scene, pos[faces].astype(np.float32))
    dirs = T.fibonacci_directions(rays).astype(np.float32).astype(np.float64)
    w = 4 * np.pi / rays
    ref = np.zeros_like(direct)
    for v in range(len(pos)):
        c = dirs @ n[v]
        up = c > 0
        o = np.repeat((pos[v] + g.offset * n[v])[None], up.sum(), 0).astype(np.float32)
        hit = scene.run(o, dirs[up].astype(np.float32), output=1)
        prim, u, vv = hit["primID"], hit["u"], hit["v"]
        ng = hit["Ng"]
        ok = (prim != -1) & ((ng * dirs[up]).sum(1) < 0)  # Embree's Ng is (p1-p0)x(p2-p0): front faces face the ray
        f = faces[prim[ok]]
        bw = np.stack([1 - u[ok] - vv[ok], u[ok], vv[ok]], 1)  # Embree: p = (1-u-v) p0 + u p1 + v p2
        t = np.einsum("rk,rkcj->rcj", bw, direct[f])
        ref[v] = kd / np.pi * np.einsum("r,rcj->cj", w * c[up][ok], t)
    # vertices on the box's edges start their rays inside the neighbouring wall's plane: hits at t ~ 0 there are
    # decided differently by two casters, so compare the others
    inner = (np.abs(pos) > 1 - 1e-9).sum(1) < 2
    assert inner.sum() >= 100
    assert np.linalg.norm(bounce[inner] - ref[inner]) < 1e-4 * np.linalg.norm(ref[inner])


def test_glossy_without_occluder_reproduces_phong_convolution(device):
    """Unoccluded, the glossy matrix is I and glossy radiance = the Phong-convolved lighting at R (and its integral)."""
    pos = np.array([[0.0, 0, 0], [1, 0, 0], [0, 0, -1]])
    faces = np.array([[0, 1, 2]])
    n = vertex_normals(pos, faces)
    g = T.Geometry.from_arrays(pos, faces, n, device=device)
    M = T.glossy_transfer(g, [0], order=4, rays=8192, mode="none")
    assert np.abs(M[0] - np.eye(16)).max() < 2e-3
    L = E.procedural("sky", resolution=32).project(4)
    eye = np.array([0.3, 1.0, 0.8])
    shin = 8.0
    got = relight.glossy_radiance(M, pos[:1], n[:1], [1.0], [shin], L, eye)[0]
    v = eye / np.linalg.norm(eye)
    r = 2 * (n[0] @ v) * n[0] - v
    conv = sh.convolve_zonal(L, sh.cosine_power_zonal(shin, 4))
    expect = sh.evaluate(conv, r)
    assert np.allclose(got, expect, rtol=3e-3)
    dirs, wq = sh.quadrature(40)
    brute = (sh.evaluate(L[:, None, :], dirs) * np.clip(dirs @ r, 0, None) ** shin * wq).sum(1)
    assert np.allclose(got, brute, rtol=5e-3)


@pytest.mark.warp_debug
def test_glossy_shadowed_matrix_matches_embree(device):
    """Shadowed glossy matrices (P-11) of the plane under the occluder equal an Embree float64 quadrature."""
    pytest.importorskip("embreex")
    from embreex import rtcore_scene as rtcs
    from embreex.mesh_construction import TriangleMesh

    pos, faces, normals = plane_under_occluder()
    g = T.Geometry.from_arrays(pos, faces, normals, device=device)
    ids = np.array([40, 10, 0])  # centre (shadowed), off-centre, corner
    rays = 512
    got = T.glossy_transfer(g, ids, order=3, rays=rays, mode="shadowed")
    scene = rtcs.EmbreeScene()
    TriangleMesh(scene, pos[faces].astype(np.float32))
    dirs = T.fibonacci_directions(rays).astype(np.float32).astype(np.float64)
    y = sh.basis(dirs, 3)
    for k, v in enumerate(ids):
        up = dirs @ normals[v] > 0
        o = np.repeat((pos[v] + g.offset * normals[v])[None], up.sum(), 0).astype(np.float32)
        free = np.asarray(scene.run(o, dirs[up].astype(np.float32), query="OCCLUDED")) == -1
        yy = y[up][free]
        ref = 4 * np.pi / rays * yy.T @ yy
        assert np.abs(got[k] - ref).max() < 4 * np.pi / rays * 2 * 0.3 + 1e-5


def test_unshadowed_relight_equals_irradiance_map_under_rotation(device):
    """Order-3 unshadowed transfer relit by a rotated sky equals kd E(R^T n) / pi from the irradiance map."""
    pos, faces = icosphere(1)
    n = vertex_normals(pos, faces)
    kd = np.array([0.8, 0.6, 0.4])
    g = T.Geometry.from_arrays(pos, faces, n, kd, device=device)
    t = T.diffuse_transfer(g, order=3, mode="unshadowed").transfer
    L = E.procedural("sky", resolution=32).project(3)
    deg = 70.0
    got = relight.diffuse_radiance(t, relight.rotated_lighting(L, deg))
    R = E.rotation_about_y(deg)
    expect = kd * I.irradiance(n @ R, L) / np.pi  # rows n R = (R^T n)^T
    assert np.abs(got - expect).max() < 2e-5 * np.abs(expect).max()


def small_scene(floor=12):
    pos, faces = icosphere(2, 0.5, (0, 0.5, 0))
    shiny = Material(kd=(0.7, 0.5, 0.3), ks=0.3, shininess=10.0)
    matte = Material(kd=(0.6, 0.6, 0.6), ks=0.0, shininess=1.0)
    return assemble_scene([("ball", pos, faces, shiny)], (floor, 1.0, matte), {}, "lights", "ball")


@pytest.mark.warp_debug
def test_bake_store_and_relight(device, tmp_path):
    """A transfer bake writes a lodprt-transfer store that reads back bit for bit and relights as the arrays say."""
    scene = small_scene()
    env = E.procedural("spots", resolution=16)
    out = tmp_path / "ball.zarr"
    res = T.bake_transfer(scene, out, sh_order=3, mode="interreflected", rays=64, bounces=2, environment=env, device=device)
    store = relight.open_transfer(out)
    assert store.attrs["format"] == "lodprt-transfer" and store.attrs["mode"] == "interreflected"
    assert np.array_equal(store.read("transfer/diffuse"), res.diffuse.transfer)
    ids = store.read("transfer/glossy_vertex_ids")
    assert np.array_equal(ids, np.nonzero(scene.object_id == 0)[0])  # only the shiny ball gets matrices
    assert store.read("transfer/glossy").shape == (len(ids), 9, 9)
    L = store.read("environment/coefficients")
    assert np.allclose(L, env.project(3))
    eye = (0.0, 1.0, 3.0)
    rad = relight.relit_radiance(store, L, eye)
    diffuse = relight.diffuse_radiance(res.diffuse.transfer, L)
    floor = scene.object_id == 1
    assert np.array_equal(rad[floor], diffuse[floor]) and (rad[ids] != diffuse[ids]).any()
    with pytest.raises(LodprtError, match="already exists"):
        T.bake_transfer(scene, out, sh_order=2, rays=8, device=device)
    (tmp_path / "other").mkdir()
    with pytest.raises(LodprtError, match="not a lodprt transfer store"):
        T.bake_transfer(scene, tmp_path / "other", sh_order=2, rays=8, device=device, overwrite=True)


def test_cli_bake_and_render_environment(tmp_path, capsys, gl):
    """`lodprt bake-environment --lod-threshold` then `render-environment --rotate` write a store and PNG frames."""
    from lodprt.cli.main import main

    mesh = tmp_path / "ball.obj"
    import trimesh

    trimesh.creation.icosphere(subdivisions=2).export(mesh)
    out = tmp_path / "ball.zarr"
    assert main(["bake-environment", str(mesh), "-o", str(out), "--environment", "sky:16", "--rays", "32",
                 "--bounces", "1", "--lod-threshold", "0.05", "--device", "cpu"]) == 0
    assert "LOD keeps" in capsys.readouterr().out
    png = tmp_path / "relit.png"
    code = main(["render-environment", str(out), "--rotate", "45", "--eye", "0", "1", "4", "--size", "64", "48",
                 "--frames", "2", "-o", str(png)])
    assert code == 0 and (tmp_path / "relit_0000.png").is_file() and (tmp_path / "relit_0001.png").is_file()
    assert main(["render-environment", str(tmp_path / "nope.zarr"), "--eye", "0", "1", "4", "-o", str(png)]) == 2
    # --overwrite with fewer frames removes the earlier run's extra ones (they were left, as turntable's once were)
    (tmp_path / "relit_00002.png").write_bytes(b"not a name the command writes")
    capsys.readouterr()
    small = [str(out), "--eye", "0", "1", "4", "--size", "16", "12", "-o", str(png), "--overwrite"]
    assert main(["render-environment", *small, "--frames", "1"]) == 0
    assert "(removed 2 stale frames of an earlier run)" in capsys.readouterr().out
    assert png.is_file() and sorted(p.name for p in tmp_path.glob("relit_*")) == ["relit_00002.png"]
    assert main(["render-environment", *small, "--frames", "3"]) == 0 and "stale" not in capsys.readouterr().out
    assert main(["render-environment", *small, "--frames", "2"]) == 0
    assert "(removed 1 stale frame of an earlier run)" in capsys.readouterr().out
    assert sorted(p.name for p in tmp_path.glob("relit_*")) == ["relit_0000.png", "relit_00002.png", "relit_0001.png"]


def test_cli_short_forms_bake_and_render_with_environment(tmp_path, capsys, gl):
    """`lodprt bake SCENE --environment ENV` and `lodprt render OUT --environment ENV --rotate DEG` do what
    bake-environment / render-environment do (the same store, a PNG); point-light options are refused clearly."""
    import trimesh

    from lodprt.cli.main import main
    from lodprt.runtime.environment_relight import open_transfer

    mesh = tmp_path / "ball.obj"
    trimesh.creation.icosphere(subdivisions=1).export(mesh)
    out = tmp_path / "ball.zarr"
    assert main(["bake", str(mesh), "--environment", "sky:16", "--sh-order", "2", "-o", str(out)]) == 0
    store = open_transfer(out)
    assert store.order == 2
    capsys.readouterr()
    assert main(["info", str(out), "--json"]) == 0  # info summarises it (it used to refuse it)
    info = json.loads(capsys.readouterr().out)
    assert info["kind"] == "lodprt transfer store" and info["attrs"]["sh_order"] == 2
    assert info["arrays"]["transfer/diffuse"]["shape"] == list(store.read("transfer/diffuse").shape)
    png = tmp_path / "relit.png"
    code = main(["render", str(out), "--environment", "stored", "--rotate", "30", "--eye", "0", "1", "4",
                 "--size", "48", "32", "-o", str(png)])
    assert code == 0 and png.is_file()
    assert main(["bake", str(mesh), "--environment", "sky:16", "--full", "-o", str(tmp_path / "x.zarr")]) == 2
    assert "point-light options" in capsys.readouterr().err
    assert main(["render", str(out), "--environment", "sky:16", "-o", str(tmp_path / "y.png")]) == 2
    assert "--eye" in capsys.readouterr().err
    eye = ["--eye", "0", "1", "4", "--size", "48", "32"]
    for extra, named in ((["--full"], "--full"), (["--per-vertex", "--wireframe"], "--wireframe, --per-vertex"),
                         (["--exposure", "1"], "--exposure"), (["--up", "1", "0", "0"], "--up"),
                         (["--no-markers"], "--no-markers")):  # used to be dropped without a word
        assert main(["render", str(out), "--environment", "stored", *eye, *extra, "-o", str(tmp_path / "z.png")]) == 2
        assert f"{named}: not with --environment" in capsys.readouterr().err
    for name in ("z.npy", "z.EXR"):  # the point-light frame's linear outputs
        assert main(["render", str(out), "--environment", "stored", *eye, "-o", str(tmp_path / name)]) == 2
        assert "writes a .png" in capsys.readouterr().err
    assert not list(tmp_path.glob("z.*"))


@pytest.fixture(scope="module")
def ball_lod():
    """The ball on a 40 x 40 floor (1,762 vertices), its shadowed transfer (cpu) and its vertex hierarchy."""
    from lodprt.model.hierarchy_build import build_hierarchy

    scene = small_scene(floor=40)
    g = T.Geometry.from_scene(scene, device="cpu")
    t = T.diffuse_transfer(g, order=3, mode="shadowed", rays=256).transfer
    return scene, t, build_hierarchy(scene.positions, scene.faces, scene.normals)


def test_transfer_cut_extremes(ball_lod):
    """Equal transfer vectors collapse to the hierarchy's roots; at threshold 0 distinct vectors keep every leaf."""
    scene, t, tree = ball_lod
    roots = T.transfer_cut(tree, np.ones_like(t), 0.0)
    assert np.array_equal(np.sort(roots), np.sort(tree.roots))
    leaves = T.transfer_cut(tree, t + np.arange(len(t))[:, None, None] * 1e-3, 0.0)
    assert np.array_equal(np.sort(leaves), np.arange(tree.num_vertices))
    with pytest.raises(LodprtError, match="lod threshold"):
        T.transfer_cut(tree, t, -1.0)


def test_transfer_cut_keeps_fewer_vertices_and_completes_close(ball_lod):
    """A 5% transfer cut keeps about half the vertices and T-15 completion relights within 1% RMS; 1% keeps more."""
    scene, t, tree = ball_lod
    L = E.procedural("sky", resolution=16).project(3)
    full = relight.diffuse_radiance(t, L)
    kept, errs = [], []
    for eps in (0.05, 0.01):
        cut = T.transfer_cut(tree, t, eps)
        done = complete_transfer(tree, scene.positions, scene.normals, cut, t[tree.vertex[cut]])
        assert np.array_equal(done[tree.vertex[cut]], t[tree.vertex[cut]])
        rad = relight.diffuse_radiance(done, L)
        kept.append(len(cut))
        errs.append(np.linalg.norm(rad - full) / np.linalg.norm(full))
    assert kept[0] < 0.7 * scene.num_vertices and kept[0] < kept[1]
    assert errs[0] < 0.01 and errs[1] <= errs[0]


def test_lod_store_completes_on_reading(ball_lod, tmp_path):
    """A bake with lod_threshold stores only the cut's vectors and the hierarchy; reading completes the rest."""
    scene, t, tree = ball_lod
    out = tmp_path / "lod.zarr"
    res = T.bake_transfer(scene, out, sh_order=3, mode="shadowed", rays=256, glossy=False, lod_threshold=0.05, tree=tree,
                          device="cpu")
    store = relight.open_transfer(out)
    assert store.attrs["vertices_kept"] == len(res.cut_nodes) < scene.num_vertices
    assert store.read("transfer/diffuse").shape == (len(res.cut_nodes), 3, 9)
    expect = complete_transfer(tree, store.read("scene/positions").astype(np.float64),
                               store.read("scene/normals").astype(np.float64), res.cut_nodes,
                               res.diffuse.transfer[tree.vertex[res.cut_nodes]].astype(np.float64))
    assert np.allclose(store.diffuse(), expect, atol=1e-6)
