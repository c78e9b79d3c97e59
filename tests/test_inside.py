"""A light or an eye inside a closed mesh (lodprt.model.inside, lodprt.runtime.inside): closed forms on a cube, a
sphere and a plane, a point inside the Stanford bunny, and the one warning of the run time and of `lodprt render`."""

import logging

import numpy as np
import pytest

from lodprt.model.inside import inside_mesh


def _cube():
    """The unit cube [-0.5, 0.5]^3, 12 triangles wound counter-clockwise seen from outside."""
    v = np.array([[x, y, z] for x in (-0.5, 0.5) for y in (-0.5, 0.5) for z in (-0.5, 0.5)])
    quads = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    f = [t for a, b, c, d in quads for t in ((a, b, c), (a, c, d))]
    return v, np.array(f)


def _sphere(n=24):
    """A UV sphere of radius 1 (n rings, 2n segments), outward winding."""
    th, ph = np.linspace(0, np.pi, n + 1)[1:-1], np.linspace(0, 2 * np.pi, 2 * n, endpoint=False)
    ring = np.stack([np.sin(th)[:, None] * np.cos(ph), np.cos(th)[:, None] + 0 * ph,
                     np.sin(th)[:, None] * np.sin(ph)], -1).reshape(-1, 3)
    v = np.vstack([[0, 1, 0], ring, [0, -1, 0]])
    m, bottom, faces = 2 * n, len(v) - 1, []
    for j in range(m):
        faces.append((0, 1 + (j + 1) % m, 1 + j))
        faces.append((bottom, 1 + (n - 2) * m + j, 1 + (n - 2) * m + (j + 1) % m))
    for i in range(n - 2):
        for j in range(m):
            a, b = 1 + i * m + j, 1 + i * m + (j + 1) % m
            faces += [(a, b, b + m), (a, b + m, a + m)]
    return v, np.array(faces)


def test_cube_and_sphere_closed_form():
    """Inside the cube iff every |coordinate| < 0.5; inside the sphere iff |p| < 1 (the polygon's inscribed radius
    is cos(pi/24)), for random points away from the surfaces; the centres are inside."""
    rng = np.random.default_rng(3)
    pts = rng.uniform(-1.4, 1.4, (200, 3))
    v, f = _cube()
    cube = np.abs(pts).max(1)
    keep = np.abs(cube - 0.5) > 0.02
    assert np.array_equal(inside_mesh(pts[keep], v, f), cube[keep] < 0.5)
    assert inside_mesh([0, 0, 0], v, f)[0] and (cube[keep] < 0.5).any()
    v, f = _sphere()
    r = np.linalg.norm(pts, axis=1)
    keep = (r < 0.97) | (r > 1.02)
    assert np.array_equal(inside_mesh(pts[keep], v, f), r[keep] < 1)
    assert inside_mesh([0, 0, 0], v, f)[0]
    assert not inside_mesh([0, 0, 0], v, f[:, ::-1])[0]  # wound inside out: the centre sees front faces


def test_plane_never_and_bunny_inside(bunny_path):
    """An open mesh (a 10 x 10 grid plane) holds no point, on it, above, below or beside; the bunny's bounding-box
    centre is inside the bunny, points above it and beside it are not."""
    from lodprt.model.scene import load_mesh

    g = np.linspace(-1, 1, 11)
    x, z = np.meshgrid(g, g)
    v = np.stack([x.ravel(), 0 * x.ravel(), z.ravel()], 1)
    f = [(i * 11 + j, (i + 1) * 11 + j, i * 11 + j + 1) for i in range(10) for j in range(10)]
    f += [(i * 11 + j + 1, (i + 1) * 11 + j, (i + 1) * 11 + j + 1) for i in range(10) for j in range(10)]
    rng = np.random.default_rng(5)
    pts = np.vstack([rng.uniform(-1.2, 1.2, (60, 3)), [[0.03, 0.0, 0.07], [0.1, 1e-9, 0.2], [0.1, -1e-9, 0.2]]])
    assert not inside_mesh(pts, v, np.array(f)).any()
    pos, faces = load_mesh(bunny_path)
    centre = 0.5 * (pos.min(0) + pos.max(0))
    got = inside_mesh([centre, centre + [0, 0.2, 0], centre + [0.3, 0, 0]], pos, faces)
    assert got.tolist() == [True, False, False]


BUNNY_INSIDE = (-0.0168, 0.11, -0.0015)  # the bunny's bounding-box centre (test above)


def test_runtime_warns_once_for_lights_and_once_for_the_eye(bunny_bake, caplog):
    """The run time logs one warning naming the light inside the bunny and the object, and one for the eye, however
    often either is set inside; lights and eyes outside are not warned about."""
    from lodprt.runtime.session import Runtime
    from lodprt.store.bake_store import open_store

    rt = Runtime(open_store(bunny_bake))
    with caplog.at_level(logging.WARNING, logger="lodprt.runtime.inside"):
        rt.set_lights([(0.05, 0.3, 0.1)])
        rt.set_camera(eye=(0.05, 0.3, 0.45), width=64, height=48)
        assert not caplog.records
        rt.set_lights([(0.05, 0.3, 0.1), BUNNY_INSIDE])
        rt.set_lights([BUNNY_INSIDE])
        rt.set_camera(eye=BUNNY_INSIDE, width=64, height=48)
        rt.set_camera(eye=(-0.01, 0.1, 0.0), width=64, height=48)
    msgs = [r.getMessage() for r in caplog.records if r.name == "lodprt.runtime.inside"]
    assert len(msgs) == 2, msgs
    assert msgs[0].startswith("light (-0.0168, 0.11, -0.0015) lies inside the closed mesh 'bunny'")
    assert msgs[1].startswith("eye (-0.0168, 0.11, -0.0015) lies inside the closed mesh 'bunny'")


def test_cli_render_with_the_eye_inside_warns_once(bunny_bake, tmp_path, caplog):
    """`lodprt render` with the eye inside the bunny writes its picture and logs the eye warning once (the CLI's
    logging prints it to stderr)."""
    pytest.importorskip("moderngl")
    from lodprt.cli.main import main

    out = tmp_path / "in.png"
    assert main(["render", str(bunny_bake), "--eye", *map(str, BUNNY_INSIDE), "--target", "0", "0.09", "0.3", "--size",
                 "64", "48", "-o", str(out)]) == 0
    warned = [r.getMessage() for r in caplog.records if "lies inside the closed mesh" in r.getMessage()]
    assert out.is_file() and len(warned) == 1 and warned[0].startswith("eye (-0.0168, 0.11, -0.0015)")


def test_store_without_hierarchy_warns_too(bunny_floor, tmp_path, caplog):
    """A store without a hierarchy (full-resolution frames, `StoreFrames`) warns the same way, once each."""
    from lodprt.precompute.bake import bake
    from lodprt.runtime.sources import frame_source
    from lodprt.store.bake_store import open_store

    path = tmp_path / "flat.zarr"
    bake(bunny_floor, path, sh_order=2, device="cpu", hierarchy=False, threshold_deg=None)
    source = frame_source(open_store(path), lod=False)
    with caplog.at_level(logging.WARNING, logger="lodprt.runtime.inside"):
        for _ in range(2):
            source.set_lights([BUNNY_INSIDE])
            source.set_camera(eye=BUNNY_INSIDE, width=32, height=24)
    msgs = [r.getMessage() for r in caplog.records if r.name == "lodprt.runtime.inside"]
    assert [m.split(" (")[0] for m in msgs] == ["light", "eye"] and all("'bunny'" in m for m in msgs)
