"""Procedural and decimated scenes: the view cut's defaults must hold on shapes other than the three shared models.

    python benchmarks/procedural.py OUT [--seed N] [--only NAME ...]

Writes, into the folder OUT, one ``NAME.toml`` scene file (docs/SCENE.md) per scene and its ``.obj`` meshes. Every
scene is made with numpy (trimesh's icosphere for the spheres, pymeshlab for the decimated bunny) from ``--seed``
(default 0), so a seed gives the same files on every machine:

* ``comb``: a slab with ``COMB_FINS`` thin fins (``FIN_WIDTH`` thick: 2.5 to 3.6% of their
  height, 0.7 to 1 ``FIN_HEIGHT``): thin features;
* ``relief``: a sphere with fine high-frequency radial displacement: fine relief;
* ``crowd``: ``CROWD_OBJECTS`` spheres, boxes and tori from 0.03 to 0.8 across: several objects, small and large on
  screen in the same view;
* ``terrain``: a wide slab whose top is a heightfield of smooth hills, flat ground between them and a few sharp
  ridges: large flat-ish areas;
* ``speck``: a small bumpy torus (0.05 across) on a floor 40 times its size: an object small on screen;
* ``bunny-coarse``: the shipped Stanford bunny (tests/data) decimated by pymeshlab's quadric edge collapse to a
  quarter of its faces: a decimated variant;
* ``rough``: the bunny decimated to just under ``MAX_TRIANGLES`` faces, its vertices moved along their normals by
  white Gaussian noise (``ROUGH_NOISE`` median edges): a raw scan's roughness, where the view cut must keep about a
  triangle a pixel.

Every closed shape (all but the bunny, which has holes in its base) is watertight and wound outward; each scene
stays under ``MAX_TRIANGLES`` object triangles so a bake at the default settings takes seconds. ``scene_meshes``
gives the arrays without writing anything (the tests use it).
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

#: object triangles per scene at most (the floor not counted)
MAX_TRIANGLES = 60_000
COMB_FINS = 16
#: fin thickness (x), height (y) and depth (z); the base is COMB_BASE wide, deep and high
FIN_WIDTH, FIN_HEIGHT, FIN_DEPTH = 0.0125, 0.5, 0.6
COMB_BASE = (1.0, 0.08, 0.7)
CROWD_OBJECTS = 24
#: ``rough``: the standard deviation of its vertices' noise along their normals, in median edge lengths
ROUGH_NOISE = 0.35
#: ``rough``: the faces pymeshlab decimates the bunny to, just under MAX_TRIANGLES
ROUGH_FACES = MAX_TRIANGLES - 1_000


def grid_box(lo, hi, n) -> tuple[np.ndarray, np.ndarray]:
    """A closed box from ``lo`` to ``hi`` whose faces are grids of ``n = (nx, ny, nz)`` cells along x, y, z, wound
    outward, shared edges welded: ``4 (nx ny + ny nz + nx nz)`` triangles."""
    lo, hi, n = np.asarray(lo, float), np.asarray(hi, float), np.asarray(n, int)
    idx = np.array(np.meshgrid(*[np.arange(k + 1) for k in n], indexing="ij")).reshape(3, -1).T
    on_surface = ((idx == 0) | (idx == n)).any(axis=1)
    idx = idx[on_surface]
    key = {tuple(k): i for i, k in enumerate(idx.tolist())}
    faces = []
    for axis in range(3):
        u, v = [a for a in range(3) if a != axis]
        for side in (0, n[axis]):
            for i in range(n[u]):
                for j in range(n[v]):
                    corner = []
                    for du, dv in ((0, 0), (1, 0), (1, 1), (0, 1)):
                        k = [0, 0, 0]
                        k[axis], k[u], k[v] = side, i + du, j + dv
                        corner.append(key[tuple(k)])
                    a, b, c, d = corner
                    # (u, v, axis) is right-handed for axis x (y, z), y (x, z -> flipped) and z (x, y)
                    outward = (side != 0) == (axis != 1)
                    faces += [(a, b, c), (a, c, d)] if outward else [(a, c, b), (a, d, c)]
    pos = lo + (hi - lo) * idx / n
    return pos, np.asarray(faces, dtype=np.int64)


def icosphere(subdivisions: int) -> tuple[np.ndarray, np.ndarray]:
    """The unit icosphere (trimesh): ``20 * 4**subdivisions`` triangles, wound outward."""
    import trimesh

    s = trimesh.creation.icosphere(subdivisions=subdivisions)
    return np.asarray(s.vertices, dtype=np.float64), np.asarray(s.faces, dtype=np.int64)


def torus(major: float, minor: float, n_major: int, n_minor: int) -> tuple[np.ndarray, np.ndarray]:
    """A torus about the y axis, wound outward: ``2 n_major n_minor`` triangles."""
    u = 2 * np.pi * np.arange(n_major) / n_major
    v = 2 * np.pi * np.arange(n_minor) / n_minor
    uu, vv = np.meshgrid(u, v, indexing="ij")
    r = major + minor * np.cos(vv)
    pos = np.stack([r * np.cos(uu), minor * np.sin(vv), r * np.sin(uu)], axis=-1).reshape(-1, 3)
    i, j = np.meshgrid(np.arange(n_major), np.arange(n_minor), indexing="ij")
    a = i * n_minor + j
    b = ((i + 1) % n_major) * n_minor + j
    c = ((i + 1) % n_major) * n_minor + (j + 1) % n_minor
    d = i * n_minor + (j + 1) % n_minor
    faces = np.concatenate([np.stack([a, d, c], -1).reshape(-1, 3), np.stack([a, c, b], -1).reshape(-1, 3)])
    return pos, faces.astype(np.int64)


def merge(parts) -> tuple[np.ndarray, np.ndarray]:
    """Concatenate (positions, faces) meshes into one (faces re-indexed)."""
    pos, faces, base = [], [], 0
    for p, f in parts:
        pos.append(p)
        faces.append(f + base)
        base += len(p)
    return np.concatenate(pos), np.concatenate(faces)


def on_ground(pos: np.ndarray) -> np.ndarray:
    """``pos`` moved so its lowest point is at y = 0."""
    return pos - np.array([0.0, pos[:, 1].min(), 0.0])


def comb(rng) -> dict:
    """A slab with COMB_FINS thin boxes standing on it (each sunk 0.01 into the slab, a separate closed part)."""
    bx, by, bz = COMB_BASE
    parts = [grid_box((-bx / 2, 0, -bz / 2), (bx / 2, by, bz / 2), (32, 2, 16))]
    pitch = bx / (COMB_FINS + 1)
    for k in range(COMB_FINS):
        x = -bx / 2 + pitch * (k + 1)
        h = FIN_HEIGHT * (0.7 + 0.3 * rng.random())
        parts.append(grid_box((x - FIN_WIDTH / 2, by - 0.01, -FIN_DEPTH / 2), (x + FIN_WIDTH / 2, by + h, FIN_DEPTH / 2),
                              (1, 24, 24)))
    pos, faces = merge(parts)
    return {"objects": [("comb", pos, faces)], "floor": (200, 1.0)}


def relief(rng) -> dict:
    """An icosphere (20,480 triangles) of radius 0.5 displaced radially by a sum of high-frequency waves."""
    pos, faces = icosphere(5)
    h = np.zeros(len(pos))
    for _ in range(6):
        k = rng.normal(size=3)
        k *= rng.uniform(25, 45) / np.linalg.norm(k)
        h += np.sin(pos @ k + rng.uniform(0, 2 * np.pi))
    pos = pos * (0.5 * (1 + 0.012 * h))[:, None]
    return {"objects": [("relief", on_ground(pos), faces)], "floor": (200, 1.0)}


def crowd(rng) -> dict:
    """CROWD_OBJECTS shapes with sizes log-uniform between 0.03 and 0.8, placed without overlap on the ground."""
    sizes = np.sort(np.exp(rng.uniform(np.log(0.03), np.log(0.8), CROWD_OBJECTS)))[::-1]
    sphere = icosphere(3)
    placed, objects = [], []
    for k, s in enumerate(sizes):
        for _ in range(1000):  # rejection sampling in a square that grows with the crowd
            xz = rng.uniform(-1.2, 1.2, 2)
            if all(np.linalg.norm(xz - q) > 0.5 * (s + t) + 0.02 for q, t in placed):
                break
        placed.append((xz, s))
        kind = k % 3
        if kind == 0:
            pos, faces = sphere[0] * (s / 2), sphere[1]
        elif kind == 1:
            pos, faces = grid_box((-s / 2, 0, -s / 2), (s / 2, s * rng.uniform(0.5, 1.5), s / 2), (6, 6, 6))
        else:
            pos, faces = torus(0.35 * s, 0.15 * s, 48, 16)
        pos = on_ground(pos) + np.array([xz[0], 0.0, xz[1]])
        objects.append((f"crowd{k:02d}", pos, faces))
    return {"objects": objects, "floor": (200, 0.3)}


def heightfield(x: np.ndarray, z: np.ndarray, rng) -> np.ndarray:
    """Smooth Gaussian hills with flat ground between them, and three sharp (tent-profile) ridges."""
    h = np.zeros_like(x)
    for _ in range(5):
        cx, cz = rng.uniform(-1.6, 1.6, 2)
        r = rng.uniform(0.25, 0.5)
        h += rng.uniform(0.1, 0.3) * np.exp(-((x - cx) ** 2 + (z - cz) ** 2) / (2 * r * r))
    for _ in range(3):
        angle, offset = rng.uniform(0, np.pi), rng.uniform(-1, 1)
        d = np.abs(x * np.cos(angle) + z * np.sin(angle) - offset)
        along = -x * np.sin(angle) + z * np.cos(angle)
        h += 0.15 * np.clip(1 - d / 0.06, 0, None) * (np.abs(along) < 1.2)
    return h


def terrain(rng) -> dict:
    """A 4 x 4 slab, 0.05 thick, whose top (100 x 100 cells) is raised by ``heightfield``."""
    pos, faces = grid_box((-2, 0, -2), (2, 0.05, 2), (100, 1, 100))
    top = pos[:, 1] > 0.025
    pos[top, 1] += heightfield(pos[top, 0], pos[top, 2], rng)
    return {"objects": [("terrain", pos, faces)], "floor": (200, 0.25)}


def speck(rng) -> dict:
    """A bumpy torus 0.05 across (about 10,000 triangles) on a floor reaching 20 of its sizes beyond it each side."""
    pos, faces = torus(0.35, 0.15, 160, 32)
    ring = pos * np.array([1.0, 0.0, 1.0])
    ring = 0.35 * ring / np.linalg.norm(ring, axis=1, keepdims=True)
    out = pos - ring
    phase = rng.uniform(0, 2 * np.pi)
    bump = 1 + 0.25 * np.sin(24 * np.arctan2(pos[:, 2], pos[:, 0]) + phase) * np.sin(6 * np.arctan2(
        out[:, 1], np.linalg.norm(out[:, [0, 2]], axis=1)))
    pos = (ring + out * bump[:, None]) * (0.05 / 1.0)
    return {"objects": [("speck", on_ground(pos), faces)], "floor": (300, 20.0)}


def decimated_bunny(target: int | None) -> tuple[np.ndarray, np.ndarray]:
    """The shipped bunny decimated by pymeshlab's quadric edge collapse to ``target`` faces (None: a quarter)."""
    import pymeshlab

    from lodprt.model.scene import load_mesh

    pos, faces = load_mesh(Path(__file__).resolve().parents[1] / "tests" / "data" / "stanford-bunny.obj.xz")
    ms = pymeshlab.MeshSet()
    ms.add_mesh(pymeshlab.Mesh(np.asarray(pos, np.float64), np.asarray(faces, np.int32)))
    ms.meshing_decimation_quadric_edge_collapse(targetfacenum=target or len(faces) // 4, preservenormal=True,
                                                preservetopology=True, optimalplacement=True)
    m = ms.current_mesh()
    return m.vertex_matrix().astype(np.float64), m.face_matrix().astype(np.int64)


def bunny_coarse(rng) -> dict:
    """The shipped bunny, decimated by pymeshlab's quadric edge collapse to a quarter of its faces."""
    return {"objects": [("bunny-coarse", *decimated_bunny(None))], "floor": (200, 1.0)}


def rough(rng) -> dict:
    """The shipped bunny decimated by pymeshlab to ``ROUGH_FACES`` faces, each vertex then moved along its normal
    by Gaussian noise of ``ROUGH_NOISE`` median edges (white: no two neighbours alike): a raw scan's roughness."""
    import trimesh

    pos, faces = decimated_bunny(ROUGH_FACES)
    mesh = trimesh.Trimesh(pos, faces, process=False)
    step = ROUGH_NOISE * float(np.median(mesh.edges_unique_length))
    pos = pos + mesh.vertex_normals * rng.normal(0.0, step, (len(pos), 1))
    return {"objects": [("rough", pos, faces)], "floor": (200, 1.0)}


#: scene name -> builder(rng) -> {"objects": [(name, positions, faces)], "floor": (resolution, margin)}
SCENES = {"comb": comb, "relief": relief, "crowd": crowd, "terrain": terrain, "speck": speck,
          "bunny-coarse": bunny_coarse, "rough": rough}
#: the scenes whose every object is closed (watertight and wound outward)
CLOSED = ("comb", "relief", "crowd", "terrain", "speck")


def scene_meshes(name: str, seed: int = 0) -> dict:
    """The scene ``name``'s meshes and floor for ``seed``, in memory."""
    return SCENES[name](np.random.default_rng([seed, list(SCENES).index(name)]))


def write_obj(path: Path, pos: np.ndarray, faces: np.ndarray) -> None:
    lines = [f"v {x:.7g} {y:.7g} {z:.7g}" for x, y, z in pos.tolist()]
    lines += [f"f {a} {b} {c}" for a, b, c in (faces + 1).tolist()]
    path.write_text("\n".join(lines) + "\n")


def write_scene(name: str, out: str | Path, seed: int = 0) -> Path:
    """Write scene ``name`` (its ``.obj`` files and ``NAME.toml``) into ``out``; returns the TOML path."""
    return write_spec(name, scene_meshes(name, seed), out)


def write_spec(name: str, spec: dict, out: str | Path) -> Path:
    """Write the scene ``spec`` (what ``scene_meshes`` returns) as ``out/NAME.toml`` and its ``.obj`` files."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    toml = []
    for obj, pos, faces in spec["objects"]:
        write_obj(out / f"{obj}.obj", pos, faces)
        toml.append(f'[[object]]\nmesh = "{obj}.obj"\nname = "{obj}"\n')
    resolution, margin = spec["floor"]
    toml.append(f"[floor]\nresolution = {resolution}\nmargin = {margin}\n[lights]\ngrid = [3, 1, 3]\n")
    path = out / f"{name}.toml"
    path.write_text("\n".join(toml))
    return path


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("out", help="folder to write the .toml and .obj files into")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--only", nargs="+", choices=list(SCENES), default=list(SCENES), metavar="NAME")
    args = p.parse_args(argv)
    for name in args.only:
        spec = scene_meshes(name, args.seed)
        path = write_spec(name, spec, args.out)
        tris = sum(len(f) for _, _, f in spec["objects"])
        print(f"{path}: {tris:,} object triangles in {len(spec['objects'])} object(s)")


if __name__ == "__main__":
    main()
