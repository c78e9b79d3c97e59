"""``lodprt export``: a frame of the run time as a binary glTF 2.0 (.glb) file (docs/EXPORT.md).

The mesh (the view cut's, or the full mesh) with POSITION, NORMAL, the triangles, per-vertex ``COLOR_0`` (the
radiance toward the eye, T-7: tone-mapped as ``lodprt render`` shows it, or over its maximum), and custom attributes
(glTF's application-specific semantics start with ``_``):

* ``_SH_i`` (i = 0 .. n-1, VEC3 float): the RGB SH coefficient i of the vertex's outgoing radiance over the view
  direction, the lights' intensities applied (the frame's coefficients): radiance toward an eye at e is
  ``sum_i _SH_i y_i((e - p) / |e - p|)`` with lodprt's real SH basis (T-5, index l(l+1)+m, no Condon-Shortley phase);
* ``_RADIANCE`` (VEC3 float): the linear radiance toward the eye, unclipped (COLOR_0 must stay in [0, 1]);
* ``_VERTEX_ID`` (SCALAR float, exact below 2^24): the vertex's index in the store.

The material is unlit (KHR_materials_unlit) with base colour 1, so a viewer shows COLOR_0 as it is. A camera node
sits at the frame's eye (looking at its target) and a KHR_lights_punctual point-light node at each light. The file is
written by :func:`glb_bytes` (glTF 2.0 binary container: a JSON chunk and one BIN chunk, every view 4-byte aligned);
trimesh's exporter is not used: it stores COLOR_0 as 8-bit, which would quantise the colours and lose the exact
map back to radiance. The Khronos glTF validator reports no issue on these files (docs/EXPORT.md).
"""

from __future__ import annotations

import json
import logging
import os
import struct
from pathlib import Path

import numpy as np

from lodprt.errors import LodprtError
from lodprt.runtime.camera import Camera, default_eye, scene_centre, view_up
from lodprt.runtime.frames import auto_white, tone_scale
from lodprt.runtime.direct_light import DEFAULT_INTERPOLATION
from lodprt.runtime.sources import frame_source
from lodprt.version import __version__

log = logging.getLogger(__name__)

VERTEX_COLORS = ("display", "linear")
#: glTF constants: component types, buffer-view targets, the triangle mode
FLOAT, UNSIGNED_INT = 5126, 5125
ARRAY_BUFFER, ELEMENT_ARRAY_BUFFER = 34962, 34963
TRIANGLES = 4
#: largest vertex id a float32 _VERTEX_ID holds exactly
MAX_EXACT_ID = 2**24
_TYPES = {1: "SCALAR", 2: "VEC2", 3: "VEC3", 4: "VEC4"}


def check_glb_output(out, overwrite: bool) -> Path:
    """The output path: a .glb in an existing folder, not an existing file unless ``overwrite``."""
    from lodprt.display.pictures import check_output

    out = Path(out)
    if out.suffix.lower() != ".glb":
        raise LodprtError(f"{out}: the output must be a .glb file")
    return check_output(out, (".glb",), overwrite=overwrite)  # the folder exists, no file replaced silently


def export_frame(store, *, sample: int | None = None, lights=None, colors=None, eye=None, target=None,
                 up=(0.0, 1.0, 0.0), fov: float = 40.0, size=(800, 600), lod: bool = True,
                 error_bound: float | None = None, alpha: float | None = None, criterion="screen",
                 interpolation: str = DEFAULT_INTERPOLATION, target_psnr=None, outside: str = "clamp",
                 white: float | None = None):
    """(frame, source) for the export: the run time (or full-resolution frames for stores without a hierarchy)
    exactly as ``lodprt render`` draws it. ``sample`` K lights the scene with stored light sample K with the bake's
    intensity (a light there, by the thesis interpolation, whose T-12 weights select that sample alone);
    ``lights`` (L, 3) with ``colors`` are point lights lit by ``interpolation``; neither: the middle light sample.
    ``eye`` defaults to the three-quarter view; ``white``: the run time's (its errors' unit; default the store's)."""
    if sample is not None and lights is not None:
        raise LodprtError("--sample and --light exclude each other")
    if lights is None:
        k = store.num_samples // 2 if sample is None else int(sample)
        store.check_sample(k)
        if colors is not None:
            raise LodprtError("--color goes with --light, not with --sample")
        lights, colors = [store.light_positions[k].tolist()], None
        interpolation = "thesis"  # the stored sample, as radiance --sample K reads it
    elif colors is not None and len(colors) != len(lights):
        raise LodprtError(f"--color: {len(colors)} given for {len(lights)} --light; give one per light or none")
    eye = tuple(eye) if eye is not None else default_eye(store)
    target = tuple(target) if target is not None else scene_centre(store)
    camera = Camera(eye=eye, target=target, up=tuple(up), fov=fov, width=int(size[0]), height=int(size[1]))
    source = frame_source(store, criterion=criterion, lod=lod, interpolation=interpolation, outside=outside,
                          error_bound=error_bound, alpha=alpha, target_psnr=target_psnr, white=white)
    source.set_lights(lights, colors)
    source.set_camera(camera)
    return source.update(), source


def vertex_colors_of(frame, mode: str, *, white: float | None, exposure: float) -> tuple[np.ndarray, dict]:
    """COLOR_0 (A, 3) float32 in [0, 1] (glTF requires it; the Khronos validator rejects other values) and what
    maps it back to radiance L: ``display`` clip(2^exposure L / white, 0, 1) in linear light, the render's tone
    mapping before the sRGB curve a glTF viewer applies on output ({"white": ...}); ``linear`` L / max(L), one
    scale for the whole mesh, so L = COLOR_0 / color_scale wherever L >= 0 (the small negative lobes of SH ringing
    read 0) ({"color_scale": 1 / max(L)})."""
    rad = np.asarray(frame.radiance, np.float64)
    if mode == "linear":
        top = float(rad.max()) if rad.size else 0.0
        scale = 1.0 / top if top > 0 and np.isfinite(top) else 1.0
        return np.clip(rad * scale, 0.0, 1.0).astype(np.float32), {"color_scale": scale}
    if mode != "display":
        raise LodprtError(f"--vertex-colors {mode!r}: choose one of {', '.join(VERTEX_COLORS)}")
    if white is None:
        white = auto_white(rad)
    scale = tone_scale(white, exposure, "--")
    return np.clip(rad * scale, 0.0, 1.0).astype(np.float32), {"white": float(white),
                                                                                   "exposure": float(exposure)}


def unit_normals(normals) -> np.ndarray:
    """(A, 3) float32 unit normals (glTF requires unit NORMAL); a zero normal becomes +y."""
    n = np.asarray(normals, np.float64)
    length = np.linalg.norm(n, axis=1, keepdims=True)
    n = np.where(length > 0, n / np.where(length > 0, length, 1.0), [0.0, 1.0, 0.0])
    return n.astype(np.float32)


def look_at_quaternion(eye, target, up) -> list[float]:
    """The glTF node rotation (x, y, z, w) of a camera at ``eye`` looking at ``target`` with ``up`` up: a glTF
    camera looks down its local -z with +y up, so the rotation's columns are (right, up, -forward)."""
    f = np.subtract(target, eye).astype(np.float64)
    f /= np.linalg.norm(f)
    r = np.cross(f, view_up(f, up))  # looking straight along up: the viewers' fallback, never a NaN rotation
    r /= np.linalg.norm(r)
    u = np.cross(r, f)
    m = np.stack([r, u, -f], axis=1)  # columns
    w = np.sqrt(max(1.0 + m[0, 0] + m[1, 1] + m[2, 2], 0.0)) / 2
    if w > 1e-6:
        q = [(m[2, 1] - m[1, 2]) / (4 * w), (m[0, 2] - m[2, 0]) / (4 * w), (m[1, 0] - m[0, 1]) / (4 * w), w]
    else:  # a half turn: the axis from the largest diagonal entry
        i = int(np.argmax(np.diag(m)))
        j, k = (i + 1) % 3, (i + 2) % 3
        t = np.sqrt(max(1.0 + m[i, i] - m[j, j] - m[k, k], 0.0)) / 2
        q = [0.0, 0.0, 0.0, (m[k, j] - m[j, k]) / (4 * t)]
        q[i], q[j], q[k] = t, (m[j, i] + m[i, j]) / (4 * t), (m[k, i] + m[i, k]) / (4 * t)
    q = np.asarray(q) / np.linalg.norm(q)
    return [float(x) for x in q]


def scene_nodes(camera, lights, light_colors) -> tuple[list[dict], dict, dict]:
    """glTF nodes for the frame's ``camera`` (a perspective camera at the eye) and its point ``lights``
    (KHR_lights_punctual, colour the RGB intensity over its largest channel, intensity that channel in lodprt's
    units), with the document's ``cameras`` and ``extensions`` entries."""
    nodes, doc = [], {}
    if camera is not None:
        distance = float(np.linalg.norm(np.subtract(camera.target, camera.eye))) or 1.0
        doc["cameras"] = [{"type": "perspective", "name": "eye", "perspective": {
            "yfov": float(np.radians(camera.fov)), "aspectRatio": float(camera.width) / float(camera.height),
            "znear": float(camera.near or 1e-3 * distance), **({"zfar": float(camera.far)} if camera.far else {})}}]
        nodes.append({"name": "eye", "camera": 0, "translation": [float(x) for x in camera.eye],
                      "rotation": look_at_quaternion(camera.eye, camera.target, camera.up)})
    punctual = []
    for k, (p, c) in enumerate(zip(np.asarray(lights, np.float64).reshape(-1, 3),
                                   np.asarray(light_colors, np.float64).reshape(-1, 3))):
        top = float(c.max())
        punctual.append({"type": "point", "name": f"light {k}", "intensity": top,
                         "color": [float(x) for x in (c / top if top > 0 else np.ones(3))]})
        nodes.append({"name": f"light {k}", "translation": [float(x) for x in p],
                      "extensions": {"KHR_lights_punctual": {"light": k}}})
    ext = {"KHR_lights_punctual": {"lights": punctual}} if punctual else {}
    return nodes, doc, ext


def glb_bytes(positions, triangles, attributes: dict[str, np.ndarray], *, extras: dict | None = None,
              unlit: bool = True, camera=None, lights=None, light_colors=None) -> bytes:
    """A binary glTF 2.0 file: one mesh of one triangle primitive, one node, one scene.

    positions (V, 3), triangles (M, 3) indices into them, attributes {semantic: (V,) or (V, k <= 4) array, stored
    float32} (NORMAL, COLOR_0, TEXCOORD_0, _CUSTOM, ...); ``extras`` goes to ``asset.extras``. Every array gets its
    own buffer view (4-byte aligned, tightly packed); POSITION carries the min/max glTF requires.
    """
    pos = np.ascontiguousarray(positions, np.float32).reshape(-1, 3)
    tri = np.ascontiguousarray(triangles, np.int64).reshape(-1, 3)
    if not len(pos) or not len(tri):
        raise LodprtError(f"glTF export: nothing to write ({len(pos)} vertices, {len(tri)} triangles)")
    if tri.min() < 0 or tri.max() >= len(pos):
        raise LodprtError(f"glTF export: triangle indices outside 0..{len(pos) - 1}")
    if not np.isfinite(pos).all():
        raise LodprtError("glTF export: non-finite vertex positions")
    blobs, views, accessors = [], [], []
    offset = 0

    def add(data: np.ndarray, component: int, target: int, *, minmax: bool = False) -> int:
        nonlocal offset
        raw = data.tobytes()
        views.append({"buffer": 0, "byteOffset": offset, "byteLength": len(raw), "target": target})
        raw += b"\0" * (-len(raw) % 4)
        blobs.append(raw)
        offset += len(raw)
        acc = {"bufferView": len(views) - 1, "componentType": component, "count": int(data.shape[0]),
               "type": "SCALAR" if target == ELEMENT_ARRAY_BUFFER else _TYPES[data.shape[1]]}
        if minmax:
            acc["min"], acc["max"] = data.min(0).tolist(), data.max(0).tolist()
        accessors.append(acc)
        return len(accessors) - 1

    prim = {"attributes": {"POSITION": add(pos, FLOAT, ARRAY_BUFFER, minmax=True)},
            "indices": add(tri.astype(np.uint32).ravel(), UNSIGNED_INT, ELEMENT_ARRAY_BUFFER), "mode": TRIANGLES}
    for name, values in attributes.items():
        a = np.ascontiguousarray(values, np.float32)
        a = a.reshape(len(a), -1)
        if len(a) != len(pos) or a.shape[1] not in _TYPES:
            raise LodprtError(f"glTF export: attribute {name} has shape {a.shape} for {len(pos)} vertices")
        if not np.isfinite(a).all():
            raise LodprtError(f"glTF export: attribute {name} has non-finite values")
        prim["attributes"][name] = add(a, FLOAT, ARRAY_BUFFER)
    more, parts, ext = scene_nodes(camera, [] if lights is None else lights,
                                   [] if light_colors is None else light_colors)
    nodes = [{"mesh": 0, "name": "lodprt"}, *more]
    doc = {"asset": {"version": "2.0", "generator": f"lodprt {__version__}"}, "scene": 0,
           "scenes": [{"nodes": list(range(len(nodes)))}], "nodes": nodes,
           "meshes": [{"name": "lodprt", "primitives": [prim]}], **parts,
           "accessors": accessors, "bufferViews": views, "buffers": [{"byteLength": offset}]}
    if extras:
        doc["asset"]["extras"] = extras
    used = []
    if unlit:
        prim["material"] = 0
        doc["materials"] = [{"name": "radiance", "pbrMetallicRoughness": {"baseColorFactor": [1.0, 1.0, 1.0, 1.0],
                             "metallicFactor": 0.0, "roughnessFactor": 1.0}, "extensions": {"KHR_materials_unlit": {}}}]
        used.append("KHR_materials_unlit")
    if ext:
        doc["extensions"] = ext
        used.extend(ext)
    if used:
        doc["extensionsUsed"] = used
    text = json.dumps(doc, separators=(",", ":")).encode()
    text += b" " * (-len(text) % 4)
    binary = b"".join(blobs)
    total = 12 + 8 + len(text) + 8 + len(binary)
    return b"".join([struct.pack("<4sII", b"glTF", 2, total), struct.pack("<I4s", len(text), b"JSON"), text,
                     struct.pack("<I4s", len(binary), b"BIN\0"), binary])


def write_glb(frame, out, *, vertex_colors: str = "display", white: float | None = None, exposure: float = 0.0,
              extras: dict | None = None, overwrite: bool = False) -> dict:
    """Write ``frame`` (a ``lodprt.runtime.Frame``) as ``out`` (.glb, written to a temporary file and renamed, so
    an existing file is replaced whole or not at all). Returns the numbers ``lodprt export`` reports."""
    out = check_glb_output(out, overwrite)
    ids = np.asarray(frame.vertex_ids)
    if len(ids) and int(ids.max()) >= MAX_EXACT_ID:
        raise LodprtError(f"{out}: vertex ids reach {int(ids.max())}; _VERTEX_ID (float32) is exact below {MAX_EXACT_ID}")
    color, mapping = vertex_colors_of(frame, vertex_colors, white=white, exposure=exposure)
    coeffs = np.asarray(frame.coefficients, np.float32)  # (A, 3, ncoef)
    attributes = {"NORMAL": unit_normals(frame.normals), "COLOR_0": color,
                  "_RADIANCE": np.asarray(frame.radiance, np.float32), "_VERTEX_ID": ids.astype(np.float32)}
    attributes.update({f"_SH_{i}": coeffs[:, :, i] for i in range(coeffs.shape[2])})
    info = {"vertex_colors": vertex_colors, **mapping,
            "sh_coefficients": int(coeffs.shape[2]), "eye": [float(x) for x in frame.camera.eye],
            "lights": np.asarray(frame.lights).tolist(), "light_colors": np.asarray(frame.light_colors).tolist(),
            "sh_basis": "lodprt real SH, index l(l+1)+m, no Condon-Shortley phase; radiance toward e = "
                        "sum_i _SH_i y_i(normalize(e - POSITION))"}
    data = glb_bytes(frame.positions, frame.triangles, attributes, extras={"lodprt": {**info, **(extras or {})}},
                     camera=frame.camera, lights=frame.lights, light_colors=frame.light_colors)
    partial = out.with_name(f".{out.name}.partial")
    try:
        partial.write_bytes(data)
        os.replace(partial, out)
    finally:
        partial.unlink(missing_ok=True)
    return {"path": out, "bytes": len(data), "vertices": int(len(frame.positions)),
            "triangles": int(len(frame.triangles)), "sh_coefficients": int(coeffs.shape[2]), **mapping}


def export_glb(store, out, *, sample: int | None = None, lights=None, colors=None, eye=None, target=None,
               up=(0.0, 1.0, 0.0), fov: float = 40.0, size=(800, 600), lod: bool = True,
               error_bound: float | None = None, alpha: float | None = None, criterion="screen",
               interpolation: str = DEFAULT_INTERPOLATION, target_psnr=None,
               outside: str = "clamp",
               vertex_colors: str = "display", white: float | None = None, exposure: float = 0.0,
               overwrite: bool = False) -> dict:
    """``lodprt export``: light ``store`` (a Store or a path; ``sample`` K or point ``lights``), take the view cut
    for the camera (``lod=False``: the full mesh) and write the frame as a .glb (:func:`write_glb`). The white of
    ``display`` colours defaults to the run time's, as ``lodprt render``'s does. Returns the numbers written."""
    if vertex_colors not in VERTEX_COLORS:
        raise LodprtError(f"--vertex-colors {vertex_colors!r}: choose one of {', '.join(VERTEX_COLORS)}")
    check_glb_output(out, overwrite)
    if isinstance(store, (str, os.PathLike)):
        from lodprt.store.bake_store import open_store

        store = open_store(store)
    if sample is None and lights is None:
        if colors is not None:  # before the middle sample stands in for the light: no --sample was given
            raise LodprtError("--color goes with --light; without --light the middle stored sample is drawn")
        sample = store.num_samples // 2
    frame, source = export_frame(store, sample=sample, lights=lights, colors=colors, eye=eye, target=target, up=up,
                                 fov=fov, size=size, lod=lod, error_bound=error_bound, alpha=alpha,
                                 criterion=criterion, interpolation=interpolation, target_psnr=target_psnr,
                                 outside=outside, white=white)
    if vertex_colors == "display" and white is None:
        white = getattr(source, "white", None) or auto_white(frame.radiance)
    extras = {"store": str(store.path), "sample": sample, "lod": bool(getattr(source, "lod", False))}
    stats = write_glb(frame, out, vertex_colors=vertex_colors, white=white, exposure=exposure, extras=extras,
                      overwrite=overwrite)
    stats["lod"] = extras["lod"]
    return stats
