"""Neighbourhood transfer (patent 5, docs/VOLUMES.md N-1..N-5): grid matrices against an Embree quadrature, the
identity where O is not seen, a sphere's shadow on a plane against the plane's own shadowed transfer bake, the
reflected light's bounds, the store and the CLI."""

import json

import numpy as np
import pytest

from lodprt.cli.main import main
from lodprt.errors import LodprtError
from lodprt.model import irradiance as I
from lodprt.model import sh
from lodprt.model.environment import procedural
from lodprt.model.scene import Material, assemble_scene, vertex_normals
from lodprt.precompute.neighbourhood import bake_neighbourhood, grid_points, transfer_matrices
from lodprt.precompute.transfer import Geometry, diffuse_transfer, fibonacci_directions
from lodprt.runtime import neighbourhood as N

KD = 0.8
MAT = Material((KD, KD, KD), 0.0, 1.0)


def icosphere(subdivisions=2, radius=0.3, centre=(0.0, 0.5, 0.0)):
    import trimesh

    m = trimesh.creation.icosphere(subdivisions=subdivisions, radius=radius)
    return np.asarray(m.vertices) + centre, np.asarray(m.faces)


def plane(n=21, size=1.0):
    """(n x n) vertices on y = 0 spanning [-size, size]^2, triangles facing +y."""
    c = np.linspace(-size, size, n)
    x, z = np.meshgrid(c, c, indexing="ij")
    pos = np.stack([x.ravel(), np.zeros(n * n), z.ravel()], 1)
    i = np.arange(n - 1)[:, None] * n + np.arange(n - 1)[None, :]
    a, b, c2, d = i.ravel(), i.ravel() + n, i.ravel() + 1, i.ravel() + n + 1
    faces = np.concatenate([np.stack([a, c2, b], 1), np.stack([b, c2, d], 1)])
    if vertex_normals(pos, faces)[0, 1] < 0:
        faces = faces[:, ::-1]
    return pos, faces


class Grid:
    """What receiver_radiance reads of a store, from a bake in memory."""

    def __init__(self, bake):
        self.bake, self.lo, self.hi = bake, bake.lo, bake.hi

    def matrices(self):
        return self.bake.matrices


@pytest.mark.warp_debug
def test_matrices_match_embree_quadrature(device):
    """Blocked and reflected parts of M_p (N-2) equal the same quadrature cast by Embree in float64, reflected
    light interpolated from O's transfer with Embree's barycentrics at front-face hits only."""
    from embreex import rtcore_scene as rtcs
    from embreex.mesh_construction import TriangleMesh

    pos, faces = icosphere(1)
    rng = np.random.default_rng(0)
    pts = rng.uniform([-0.55, -0.05, -0.55], [0.55, 1.05, 0.55], size=(24, 3))
    pts = pts[np.linalg.norm(pts - [0, 0.5, 0], axis=1) > 0.35]
    own = rng.uniform(0, 0.3, size=(len(pos), 3, 4))
    m = transfer_matrices(pos, faces, pts, order=2, transferred_order=3, rays=64, object_transfer=own, device=device)
    dirs = fibonacci_directions(64).astype(np.float32).astype(np.float64)
    scene = rtcs.EmbreeScene()
    TriangleMesh(scene, pos[faces].astype(np.float32))
    o = np.repeat(pts, 64, 0).astype(np.float32)
    d = np.tile(dirs, (len(pts), 1)).astype(np.float32)
    hit = scene.run(o, d, output=1)
    prim = np.asarray(hit["primID"]).reshape(len(pts), 64)
    u, v = np.asarray(hit["u"]).reshape(len(pts), 64), np.asarray(hit["v"]).reshape(len(pts), 64)
    ng = np.asarray(hit["Ng"]).reshape(len(pts), 64, 3)
    y = sh.basis(dirs, 3)
    w = 4 * np.pi / 64
    ref = np.zeros((len(pts), 3, 9, 4))
    for p in range(len(pts)):
        blocked = prim[p] >= 0
        ref[p] -= w * np.einsum("ri,rj->ij", y[blocked], y[blocked][:, :4])[None]
        for r in np.flatnonzero(blocked & ((ng[p] * dirs).sum(1) < 0)):
            f = faces[prim[p, r]]
            t = (1 - u[p, r] - v[p, r]) * own[f[0]] + u[p, r] * own[f[1]] + v[p, r] * own[f[2]]  # (3, 4)
            ref[p] += w * y[r][None, :, None] * t[:, None, :]
    ref[:, :, np.arange(4), np.arange(4)] += 1
    assert (prim >= 0).sum() > 50  # enough rays meet the ball for the comparison to mean something
    assert np.abs(m - ref).max() < 2e-5


def test_identity_where_object_is_not_seen():
    """A point from which no ray meets O gets M = I exactly (N-2), its receiver the plain unshadowed diffuse
    radiance kd E(N)/pi of the 9-coefficient irradiance (N-5 against R-H's formula)."""
    pos, faces = icosphere(1, radius=0.1, centre=(0, 5, 0))
    pts = np.array([[0.0, 0.0, 0.0], [1.0, 0.2, -0.5]])
    dirs = fibonacci_directions(32)
    to = (np.array([0.0, 5.0, 0.0])[None] - pts) / np.linalg.norm([0.0, 5.0, 0.0] - pts, axis=1, keepdims=True)
    assert (dirs @ to.T).max() < np.cos(np.arcsin(0.1 / 4.8))  # no direction of the set comes near the ball
    m = transfer_matrices(pos, faces, pts, order=3, transferred_order=3, rays=32, device="cpu")
    assert np.array_equal(m, np.broadcast_to(np.eye(9, dtype=np.float32), m.shape))
    lighting = procedural("sky", resolution=32).project(3)
    nrm = np.random.default_rng(1).normal(size=(len(pts), 3))
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    lq = N.transferred_lighting(m, lighting)
    got = N.diffuse_exit(lq, nrm, np.full(3, KD))
    assert np.allclose(got, KD * I.irradiance(nrm, lighting) / np.pi, rtol=1e-6, atol=1e-9)


def sphere_over_plane():
    sp, sf = icosphere(2)
    pp, pf = plane()
    with_o = assemble_scene([("ball", sp, sf, MAT), ("plane", pp, pf, MAT)], None, {}, "lights", "ball over plane")
    without = assemble_scene([("plane", pp, pf, MAT)], None, {}, "lights", "plane")
    return with_o, without, pp, len(sp)


def test_sphere_shadow_on_plane_matches_shadowed_bake():
    """The plane as a receiver of the ball's neighbourhood (16^3 grid, 256 rays, occlusion only) is darkened as the
    plane's own shadowed transfer bake of the ball + plane scene darkens it: RMS error under 2.5% and worst
    under 20% of the deepest darkening (measured 1.6% and 12%: trilinear interpolation of a shadow that sharpens
    near the ball); without the ball (or outside the grid) the darkening vanishes."""
    scene, bare, pp, nb = sphere_over_plane()
    lighting = procedural("sky", resolution=32).project(3)
    t1 = diffuse_transfer(Geometry.from_scene(scene, device="cpu"), order=3, mode="shadowed", rays=256).transfer[nb:]
    t0 = diffuse_transfer(Geometry.from_scene(bare, device="cpu"), order=3, mode="shadowed", rays=256).transfer
    r1, r0 = np.einsum("vci,ci->vc", t1, lighting), np.einsum("vci,ci->vc", t0, lighting)
    dark_ref = r0 - r1
    res = bake_neighbourhood(scene, "ball", None, grid=(16, 16, 16), margin=1.8, sh_order=3, rays=256,
                             reflection=False, device="cpu")
    nrm = np.tile([0.0, 1.0, 0.0], (len(pp), 1))
    got, inside = N.receiver_radiance(Grid(res), lighting, pp, nrm, np.full(3, KD))
    plain, outside = N.receiver_radiance(Grid(res), lighting, pp + [10.0, 0, 0], nrm, np.full(3, KD))
    assert inside.all() and not outside.any()
    dark = plain - got
    err = np.abs(dark - dark_ref)
    assert dark_ref.max() > 0.2 * r0.max()  # a real shadow
    assert np.sqrt((err**2).mean()) < 0.025 * dark_ref.max()
    assert err.max() < 0.2 * dark_ref.max()
    # O removed: the plane's bake without the ball, and a receiver outside the grid, see no darkening
    assert np.abs(plain - r0).max() < 1e-3 * r0.max()
    assert np.array_equal(plain, N.diffuse_exit(np.repeat(lighting[None], len(pp), 0), nrm, np.full(3, KD)))


def test_reflected_light_lies_between_occlusion_and_no_object():
    """Under a uniform white sky the ball reflects at most kd of what it blocks: receiver radiance with reflection
    is above occlusion alone and below the unoccluded sky, at every plane vertex under the ball."""
    scene, _, pp, _ = sphere_over_plane()
    white = np.zeros((3, 9))
    white[:, 0] = np.sqrt(4 * np.pi)
    nrm = np.tile([0.0, 1.0, 0.0], (len(pp), 1))
    out = {}
    for refl in (False, True):
        res = bake_neighbourhood(scene, "ball", None, grid=(8, 8, 8), margin=1.8, sh_order=3, rays=128,
                                 reflection=refl, bounces=0, device="cpu")
        out[refl], _ = N.receiver_radiance(Grid(res), white, pp, nrm, np.full(3, KD))
    under = np.linalg.norm(pp[:, [0, 2]], axis=1) < 0.3
    assert (out[True][under] > out[False][under] + 1e-3).all()
    assert (out[True][under] < KD).all()  # KD x the unit sky's irradiance / pi


def test_cli_bake_neighbourhood_and_render_receiver(tmp_path, gl, capsys):
    """bake-neighbourhood writes a store; render-environment draws it with --receiver --at; bad input exits 2."""
    import trimesh

    sp, sf = icosphere(1, centre=(0, 0, 0))
    trimesh.Trimesh(sp, sf, process=False).export(tmp_path / "ball.obj")
    pp, pf = plane(9)
    trimesh.Trimesh(pp, pf, process=False).export(tmp_path / "plane.obj")
    (tmp_path / "s.toml").write_text('[[object]]\nmesh = "ball.obj"\nname = "ball"\ntranslate = [0, 0.5, 0]\n')
    out = tmp_path / "n.zarr"
    assert main(["bake-neighbourhood", str(tmp_path / "s.toml"), "--object", "ball", "--grid", "6", "6", "6",
                 "--rays", "32", "--environment", "sky:16", "-o", str(out), "--device", "cpu"]) == 0
    store = N.open_neighbourhood(out)
    assert store.matrices().shape == (6, 6, 6, 3, 9, 9) and store.attrs["object"] == "ball"
    capsys.readouterr()
    assert main(["info", str(out), "--json"]) == 0  # info summarises it (it used to say: not a lodprt store)
    info = json.loads(capsys.readouterr().out)
    assert info["kind"] == "lodprt neighbourhood store" and info["attrs"]["object"] == "ball"
    assert [6, 6, 6, 3, 9, 9] in [a["shape"] for a in info["arrays"].values()]
    png = tmp_path / "n.png"
    assert main(["render-environment", str(out), "--receiver", str(tmp_path / "plane.obj"), "--at", "0", "0.05", "0",
                 "--eye", "0", "1.5", "2", "--size", "64", "48", "-o", str(png)]) == 0
    assert png.stat().st_size > 0
    assert main(["bake-neighbourhood", str(tmp_path / "s.toml"), "--object", "car", "-o", str(tmp_path / "x.zarr")]) == 2
    assert "no such object" in capsys.readouterr().err
    assert main(["bake-neighbourhood", str(tmp_path / "s.toml"), "--object", "ball", "--grid", "1", "4", "4",
                 "-o", str(tmp_path / "x.zarr")]) == 2
    assert "at least 2" in capsys.readouterr().err
    with pytest.raises(LodprtError, match="not a lodprt neighbourhood store"):
        N.open_neighbourhood(tmp_path / "s.toml")
    grid = grid_points([0, 0, 0], [1, 2, 3], (2, 3, 4))
    assert np.allclose(grid[-1, -1, -1], [1, 2, 3]) and np.allclose(grid[0, 1, 0], [0, 1, 0])


def test_a_flat_box_and_a_non_finite_point_stay_outside_the_arithmetic():
    """A flat object with margin 0 gets a box of 1e-3 of its extent along the flat axis (N-4 divided 0 by 0 there
    and indexed with the minimum int64); a NaN receiver point is outside the grid and gets 0, as any outside one."""
    from lodprt.precompute.neighbourhood import neighbourhood_box

    plane = np.array([[-2, 0, -2], [2, 0, -2], [2, 0, 2], [-2, 0, 2.0]])
    lo, hi = neighbourhood_box(plane, 0.0)
    np.testing.assert_allclose(hi - lo, [4, 4e-3, 4])
    np.testing.assert_allclose((lo + hi) / 2, [0, 0, 0], atol=1e-12)
    values = np.arange(27.0).reshape(3, 3, 3)
    out, inside = N.interpolate(values, lo, hi, [[0, 0, 0], [np.nan, 0, 0], [0, np.inf, 0]])
    assert inside.tolist() == [True, False, False] and out[0] == values[1, 1, 1] and out[1] == out[2] == 0


def test_an_ambiguous_object_name_is_refused():
    """Two objects named alike: --object NAME names the clash (it baked the first one without a word)."""
    from lodprt.precompute.neighbourhood import object_mesh

    tet = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1.0]])
    faces = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
    mat = Material(kd=(0.5, 0.5, 0.5), ks=0.0, shininess=1.0)
    scene = assemble_scene([("ball", tet, faces, mat), ("ball", tet + 3, faces, mat)], None, {}, "lights", "dup")
    with pytest.raises(LodprtError, match="--object 'ball': 2 objects have that name"):
        object_mesh(scene, "ball")
