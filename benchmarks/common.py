"""What every benchmark shares: the thesis scene, argument parsing, and writing the table, JSON and plot."""

from __future__ import annotations

import argparse
import json
import platform
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
#: The test meshes shipped with the project (stanford-bunny, spot, fandisk): xz-compressed OBJ files, read by
#: lodprt's mesh loader to exactly the arrays of the plain OBJ files (tests/data/README.md).
MODELS = REPO / "tests" / "data"


def model(name: str) -> Path:
    """The shipped test mesh ``name`` (``"stanford-bunny"``, ``"spot"`` or ``"fandisk"``)."""
    return MODELS / f"{name}.obj.xz"

RESULTS = REPO / "benchmarks" / "results"


def parser(description: str) -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(description=description)
    p.add_argument("--quick", action="store_true", help="a small version that runs in seconds (CI smoke test)")
    p.add_argument("--json", metavar="PATH", default=None, help="write machine-readable results here "
                   "(default: benchmarks/results/<name>.json)")
    p.add_argument("--device", default=None, help="Warp device (default: cuda if present, else cpu)")
    return p


def thesis_scene(*, quick: bool, sh_order: int | None = None):
    """The Stanford bunny on a 380 x 380 floor with 3 x 1 x 3 light samples (quick: 100 x 100, 2 x 1 x 1)."""
    from lodprt.model.scene import THESIS_MATERIAL, assemble_scene, load_mesh

    pos, faces = load_mesh(model("stanford-bunny"))
    res = 100 if quick else 380
    grid = [2, 1, 1] if quick else [3, 1, 3]
    return assemble_scene([("bunny", pos, faces, THESIS_MATERIAL)], (res, 1.0, THESIS_MATERIAL), {"grid": grid},
                          "lights", f"stanford-bunny + {res}x{res} floor")


def meshopt_halving(positions, faces) -> float:
    """Seconds meshoptimizer's ``simplify`` (PyPI ``meshoptimizer``, the ``bench`` extra) takes to halve the mesh
    (target half the indices, error bound 1: the face count decides), the yardstick of the hierarchy build."""
    import time

    import meshoptimizer

    idx = np.ascontiguousarray(np.asarray(faces, np.uint32).ravel())
    pos = np.ascontiguousarray(np.asarray(positions, np.float32))
    out = np.empty_like(idx)
    t = time.perf_counter()
    meshoptimizer.simplify(out, idx, pos, target_index_count=len(idx) // 2, target_error=1.0)
    return time.perf_counter() - t


def table(rows: list[dict], columns: list[tuple[str, str, str]]) -> str:
    """Rows as a fixed-width text table; columns are (key, header, format)."""
    head = "  ".join(f"{h:>{max(len(h), 12)}}" for _, h, _ in columns)
    lines = [head, "-" * len(head)]
    for r in rows:
        cells = []
        for key, h, fmt in columns:
            v = r.get(key, "")
            cells.append(f"{(format(v, fmt) if v != '' else ''):>{max(len(h), 12)}}")
        lines.append("  ".join(cells))
    return "\n".join(lines)


def environment(device: str) -> dict:
    import warp

    return {"python": platform.python_version(), "machine": platform.machine(), "warp": warp.config.version,
            "device": device, "numpy": np.__version__}


def write(name: str, results: dict, json_path: str | None) -> Path:
    """Write ``results`` (which name their ``"benchmark"``, the script's stem) with the code fingerprint of that
    script (``benchmarks/fingerprint.py``): ``benchmarks/report.py --check`` compares it with the current code's."""
    from fingerprint import code_fingerprint

    RESULTS.mkdir(parents=True, exist_ok=True)
    path = Path(json_path) if json_path else RESULTS / f"{name}.json"
    script = REPO / "benchmarks" / f"{results['benchmark']}.py"
    results["code_fingerprint"], results["code_files"] = code_fingerprint(script)
    path.write_text(json.dumps(results, indent=2))
    return _shown(path)


def plot_path(name: str) -> Path:
    RESULTS.mkdir(parents=True, exist_ok=True)
    return _shown(RESULTS / f"{name}.png")


def _shown(path: Path) -> Path:
    """The path relative to the working directory when it lies below it (what the scripts print)."""
    try:
        return path.resolve().relative_to(Path.cwd())
    except ValueError:
        return path
