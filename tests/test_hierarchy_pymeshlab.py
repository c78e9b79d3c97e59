"""The pymeshlab-seeded hierarchy build (``build_hierarchy(method="pymeshlab")``): the same kind of hierarchy as the
rounds build (a binary forest of legal half-edge collapses, cones and radii holding their leaves), following
pymeshlab's halvings level by level, with tiles and worker processes; ``bake --hierarchy pymeshlab`` end to end."""

import numpy as np
import pytest

from lodprt.errors import LodprtError
from lodprt.model import hierarchy_pymeshlab
from lodprt.model.hierarchy_build import build_hierarchy
from lodprt.model.hierarchy_levels import levels_from_chain, mesh_groups, pymeshlab_chain
from lodprt.model.hierarchy_pymeshlab import removal_levels
from lodprt.model.hierarchy_rounds import NEVER
from lodprt.model.scene import vertex_normals
from lodprt.runtime.view_cut import Cut
from test_hierarchy import check_cones, check_forest, check_radii, replay_collapses, wavy_grid


@pytest.fixture(scope="module")
def pml(bunny_floor):
    """The pymeshlab build of the bunny on its 40 x 40 floor (two components, in this process)."""
    s = bunny_floor
    return build_hierarchy(s.positions, s.faces, s.normals, method="pymeshlab", workers=1)


def several_components():
    """Three separate grids (two curved, one flat and tilted): positions, faces, normals."""
    pa, fa = wavy_grid(22, seed=3)
    pb, fb = wavy_grid(15, lift=4.0, seed=4)
    t = np.linspace(0, 9, 18)
    x, z = np.meshgrid(t, t, indexing="ij")
    pc = np.c_[x.ravel() + 30, 0.2 * z.ravel(), z.ravel()]
    i = (np.arange(17)[:, None] * 18 + np.arange(17)[None, :]).ravel()
    fc = np.r_[np.c_[i, i + 1, i + 19], np.c_[i, i + 19, i + 18]]
    pos = np.r_[pa, pb, pc]
    faces = np.r_[fa, fb + len(pa), fc + len(pa) + len(pb)]
    return pos, faces, vertex_normals(pos, faces)


def follows_levels(h, level):
    """How many collapses, from the first in creation order, follow the levels: a non-decreasing phase p with
    level[v] <= p < level[u] for each (v the collapsed vertex, u the survivor); the rest are the final rounds."""
    V = h.num_vertices
    u, v = h.vertex[V:], h.vertex[h.children[V:, 1]]
    p = 0
    for k, (a, b) in enumerate(zip(level[v].tolist(), level[u].tolist())):
        p = max(p, a)
        if not p < b:
            return k
    return len(u)


def test_bunny_floor_is_a_valid_forest_with_cones_and_radii(bunny_floor, pml):
    """On the bunny + floor: a binary forest of half-edge collapses over the original vertices, every cone holds
    its leaves' normals, every sampled radius its leaves' positions, the full cut gives back the original faces,
    and the base is as small as the rounds build's (within 2x)."""
    s = bunny_floor
    assert pml.method == "pymeshlab"
    check_forest(pml, s.num_vertices, s.referenced)
    check_cones(pml, s.normals)
    check_radii(pml, s.positions, np.random.default_rng(1).choice(np.arange(s.num_vertices, pml.num_nodes), 200,
                                                                   replace=False))
    np.testing.assert_array_equal(Cut.full(pml, s.faces).triangles(), s.faces)
    assert len(pml.roots) < 2 * 1187  # the rounds build keeps 1,187 roots here (docs/HIERARCHY.md)


def test_bunny_floor_collapses_are_legal_and_follow_pymeshlab(bunny_floor, pml):
    """Replayed one by one (``replay_collapses``, the rounds build's oracle) every collapse is legal, and all but
    the final unrestricted rounds follow pymeshlab's halvings: a vertex pymeshlab removed at level L collapses in
    phase L or later into a vertex that survives that phase."""
    s = bunny_floor
    replay_collapses(s.positions, s.faces, pml, error_vectors=False)
    level, _ = removal_levels(s.positions, s.faces, mesh_groups(s.num_vertices, s.faces), workers=1)
    collapses = pml.num_nodes - s.num_vertices
    assert follows_levels(pml, level) > 0.98 * collapses
    assert np.count_nonzero(level < NEVER) > 0.95 * collapses  # pymeshlab removed nearly all that collapsed


def test_untiled_levels_equal_the_plain_pymeshlab_chain(bunny_floor):
    """Below the tile size, a group's levels are exactly those of pymeshlab's plain chained halvings of it."""
    s = bunny_floor
    groups = mesh_groups(s.num_vertices, s.faces)
    level, n = removal_levels(s.positions, s.faces, groups, keep_boundary=True, workers=1)
    chain = pymeshlab_chain(s.positions, s.faces, groups=groups, keep_boundary=True)
    want = levels_from_chain(s.num_vertices, s.faces.astype(np.int64), chain)
    np.testing.assert_array_equal(np.where(level == NEVER, 0, level), want)
    assert n == len(chain)


def test_tiles_and_workers_on_several_components(monkeypatch):
    """Three components, tiled (tiles of 150 vertices, borders locked, then the stitched borders) on two worker
    processes: the same invariants, every collapse legal with its error vector (brute force), no collapse across
    components, and the tiled levels lock every tile border in the first stage."""
    monkeypatch.setattr(hierarchy_pymeshlab, "PARALLEL_VERTICES", 0)
    monkeypatch.setattr(hierarchy_pymeshlab, "TILE_VERTICES", 150)
    pos, faces, normals = several_components()
    V = len(pos)
    h = build_hierarchy(pos, faces, normals, method="pymeshlab", workers=2)
    check_forest(h, V, np.ones(V, bool))
    check_cones(h, normals)
    check_radii(h, pos, np.arange(V, h.num_nodes, 7))
    replay_collapses(pos, faces, h)
    group = mesh_groups(V, faces)
    np.testing.assert_array_equal(group[h.vertex[V:]], group[h.vertex[h.children[V:, 1]]])
    assert len(h.roots) <= 3 * (64 + 2) + 30
    level, _ = removal_levels(pos, faces, group, workers=2)
    assert follows_levels(h, level) > 0.9 * (h.num_nodes - V)
    # the first stage of the big grid (484 vertices: 4 tiles) never removes a border vertex of its tiles
    big = faces[: 2 * 21 * 21]
    tile, border = hierarchy_pymeshlab.tiles(pos, big, 150)
    assert len(np.unique(tile)) >= 3 and border[:484].any()
    first = [int(hierarchy_pymeshlab.decimate_part(pos[np.unique(big[tile == t])], np.searchsorted(
        np.unique(big[tile == t]), big[tile == t]), border[np.unique(big[tile == t])], 64, False)[2])
        for t in np.unique(tile)]
    assert (level[border] > max(first)).all()


def test_unknown_method_is_refused():
    """An unknown build is a one-line LodprtError naming the choices, from the API and from the command line."""
    pos, faces = wavy_grid(5)
    with pytest.raises(LodprtError, match="choose one of sequential, rounds, pymeshlab"):
        build_hierarchy(pos, faces, vertex_normals(pos, faces), method="qslim")
    from lodprt.cli.main import main

    assert main(["bake", "demo", "-o", "never.zarr", "--hierarchy", "qslim"]) == 2


def test_bake_with_the_pymeshlab_hierarchy_renders(tmp_path, bunny_path):
    """``lodprt bake --hierarchy pymeshlab`` on a small scene: the store records the method, and the run time
    opens it and draws triangles."""
    from lodprt.cli.main import main
    from lodprt.runtime.session import Runtime
    from lodprt.store.bake_store import open_store

    pos, faces = wavy_grid(30)
    mesh = tmp_path / "bump.obj"
    mesh.write_text("".join(f"v {x} {y} {z}\n" for x, y, z in pos / 10 + [0, 0.2, 0])
                    + "".join(f"f {a + 1} {b + 1} {c + 1}\n" for a, b, c in faces))
    toml = tmp_path / "bump.toml"
    toml.write_text(f'[[object]]\nmesh = "{mesh.as_posix()}"\n[floor]\nresolution = 20\n[lights]\ngrid = [2, 1, 1]\n')
    out = tmp_path / "bump.zarr"
    assert main(["bake", str(toml), "-o", str(out), "--hierarchy", "pymeshlab", "--device", "cpu"]) == 0
    store = open_store(out)
    assert store.root["hierarchy"].attrs["method"] == "pymeshlab"
    assert store.hierarchy().method == "pymeshlab"
    from lodprt.runtime.camera import default_eye, scene_centre

    rt = Runtime(store, device="cpu")
    rt.set_camera(default_eye(store), scene_centre(store), width=320, height=240)
    frame = rt.update()
    assert 0 < frame.stats["triangles"] <= len(store.faces)
    assert rt.h.method == "pymeshlab" and rt.h.num_nodes > store.num_vertices
