"""Mitsuba 3 as the benchmarks' independent renderer (``pip install 'lodprt[reference]'``): a lodprt scene drawn by
Mitsuba's path tracer with the same camera, Lambert materials and a point light, and the PSNR of display values."""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np


def require_mitsuba():
    try:
        import mitsuba as mi
    except ImportError:
        sys.exit("this benchmark's Mitsuba check needs Mitsuba 3: pip install 'lodprt[reference]' (or pip install "
                 "'mitsuba>=3.5'); the variant scalar_rgb runs on the CPU")
    mi.set_variant("scalar_rgb")
    return mi


def mitsuba_image(scene, light, intensity, bounces: int, size, spp: int, tmp: Path, *, camera) -> np.ndarray:
    """Linear RGB (H, W, 3) of ``scene`` by Mitsuba's path tracer: Lambert kd, a point light of intensity pi I
    (lodprt's ``kd I cos / d^2`` is ``(kd / pi) (pi I) cos / d^2``), max_depth = bounces + 2 (0: direct light
    only), ``camera`` (eye, target, vertical fov in degrees)."""
    mi = require_mitsuba()
    import trimesh

    eye, target, fov = camera
    shapes = {}
    for k, name in enumerate(scene.object_names):
        sel = scene.object_id == k
        remap = np.cumsum(sel) - 1
        faces = scene.faces[sel[scene.faces[:, 0]]]
        mesh = trimesh.Trimesh(scene.positions[sel], remap[faces], vertex_normals=scene.normals[sel], process=False)
        ply = tmp / f"{name}.ply"
        mesh.export(ply, vertex_normal=True)
        kd = scene.materials[scene.material_id[np.flatnonzero(sel)[0]]].kd
        shapes[name] = {"type": "ply", "filename": str(ply), "face_normals": False,
                        "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": list(kd)}}}
    w, h = size
    sensor = {"type": "perspective", "fov": float(fov), "fov_axis": "y", "near_clip": 1e-3, "far_clip": 100.0,
              "to_world": mi.ScalarTransform4f().look_at(origin=[float(x) for x in eye],
                                                         target=[float(x) for x in target], up=[0, 1, 0]),
              "film": {"type": "hdrfilm", "width": w, "height": h, "rfilter": {"type": "box"}, "pixel_format": "rgb"},
              "sampler": {"type": "independent", "sample_count": spp}}
    desc = {"type": "scene", "integrator": {"type": "path", "max_depth": bounces + 2, "hide_emitters": True},
            "sensor": sensor, "light": {"type": "point", "position": [float(x) for x in light],
                                        "intensity": {"type": "rgb", "value": [math.pi * c for c in intensity]}}}
    desc.update(shapes)
    img = mi.render(mi.load_dict(desc))
    return np.asarray(img, np.float64)[:, :, :3]


def psnr(a: np.ndarray, b: np.ndarray, white: float, mask=None) -> float:
    """PSNR of display values clip(L / white, 0, 1); ``mask`` restricts it to some pixels."""
    x, y = np.clip(a / white, 0, 1), np.clip(b / white, 0, 1)
    if mask is not None:
        x, y = x[mask], y[mask]
    return float(10 * np.log10(1.0 / max(np.mean((x - y) ** 2), 1e-20)))
