"""Vertex hierarchy build: time, peak memory and shape, against pymeshlab's plain QEM decimation in the same run.

    python benchmarks/hierarchy.py [--quick] [--json PATH]

Peak memory is the process's peak resident set after each build (cumulative, so an upper bound for later rows).
Meshes: the Stanford bunny on a 380 x 380 floor (180,347 vertices), spot and fandisk (quick: the bunny on a
60 x 60 floor). Baseline: pymeshlab decimating the same mesh straight to the hierarchy's base size, one call.
"""

from __future__ import annotations

import resource
import time

import numpy as np

from common import environment, model, parser, plot_path, table, thesis_scene, write


def meshes(quick: bool):
    from lodprt.model.scene import THESIS_MATERIAL, assemble_scene, load_mesh

    if quick:
        pos, faces = load_mesh(model("stanford-bunny"))
        yield "bunny + 60x60 floor", assemble_scene([("bunny", pos, faces, THESIS_MATERIAL)], (60, 1.0, THESIS_MATERIAL),
                                                    {}, "l", "q")
        return
    yield "bunny + 380x380 floor", thesis_scene(quick=False)
    for name in ("spot", "fandisk"):
        pos, faces = load_mesh(model(name))
        yield name, assemble_scene([(name, pos, faces, THESIS_MATERIAL)], None, {}, "l", name)


def pymeshlab_baseline(scene, target_vertices: int) -> float:
    import pymeshlab

    ms = pymeshlab.MeshSet()
    ms.add_mesh(pymeshlab.Mesh(vertex_matrix=scene.positions, face_matrix=scene.faces))
    t = time.perf_counter()
    ms.meshing_decimation_quadric_edge_collapse(targetfacenum=max(2 * target_vertices, 8), optimalplacement=False,
                                                preservetopology=True, preserveboundary=True)
    return time.perf_counter() - t


def main():
    args = parser(__doc__.splitlines()[0]).parse_args()
    from lodprt.model.hierarchy_build import build_hierarchy

    rows = []
    for name, scene in meshes(args.quick):
        h = build_hierarchy(scene.positions, scene.faces, scene.normals)
        peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024  # process peak so far (Linux: KiB)
        base = pymeshlab_baseline(scene, len(h.roots))
        rows.append({
            "mesh": name,
            "vertices": scene.num_vertices,
            "triangles": len(scene.faces),
            "nodes": h.num_nodes,
            "roots": len(h.roots),
            "depth": h.depth,
            "levels": h.levels,
            "build_s": h.build_seconds,
            "pymeshlab_s": base,
            "ratio": h.build_seconds / base,
            "peak_mib": peak / 2**20,
            "bytes_per_node": h.nbytes / h.num_nodes,
        })
        print(f"{name}: {h.build_seconds:.1f} s", flush=True)
    print(table(rows, [("mesh", "mesh", "s"), ("vertices", "vertices", ","), ("nodes", "nodes", ","), ("roots", "roots", ","),
                       ("depth", "depth", "d"), ("build_s", "build s", ".2f"), ("pymeshlab_s", "pymeshlab s", ".2f"),
                       ("ratio", "x pymeshlab", ".1f"), ("peak_mib", "peak RSS MiB", ".0f"),
                       ("bytes_per_node", "B/node", ".1f")]))
    name = "hierarchy" + ("-quick" if args.quick else "")
    print("wrote", write(name, {"benchmark": "hierarchy", "quick": args.quick, "environment": environment("cpu"),
                                "rows": rows}, args.json))
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 3.5))
    y = np.arange(len(rows))
    ax.barh(y + 0.2, [r["build_s"] for r in rows], 0.4, label="lodprt hierarchy (rounds of half-edge collapses)")
    ax.barh(y - 0.2, [r["pymeshlab_s"] for r in rows], 0.4, label="pymeshlab QEM to the same base size")
    ax.set_yticks(y, [f"{r['mesh']}\n{r['vertices']:,} v" for r in rows])
    ax.set_xlabel("seconds")
    ax.set_title("Vertex hierarchy build")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(plot_path(name), dpi=120)
    print("wrote", plot_path(name))


if __name__ == "__main__":
    main()
