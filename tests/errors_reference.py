"""The float64 numpy evaluation of the view cut's per-node errors (T-13, T-14, S-1, S-2): slow and obviously
correct, the tests' oracle for the Warp kernel ``lodprt.kernels.runtime.view_errors`` (``Runtime.node_errors``)."""

from __future__ import annotations

import math

import numpy as np

from lodprt.errors import LodprtError
from lodprt.model import sh
from lodprt.runtime.frames import display
from lodprt.runtime.node_bounds import NodeErrors


#: S-1's constants as docs/RUNTIME.md states them (the oracle's own copies, not the production criterion's): the
#: default bound E0 and the share of the screen a node may cover before its shading term grows
SCREEN_DEFAULT_BOUND = 0.8
AREA_SHARE = 1.0 / 32768


def criterion_error(rt, culled, e_geo, e_lumi, footprint, e_detail) -> np.ndarray:
    """The error compared with the bound (0 where culled), from the criterion's settings only: T-14 ``alpha e_geo
    + (1 - alpha) e_lumi`` for "thesis"; for "screen" (S-1) ``max(E0 g_px / tau_px, e_detail cover)``: the
    geometric error in pixels at the exchange rate E0 / tau_px (E0 the default bound, or the steered bound under a
    target_psnr; tau_px the pixel tolerance: at the default bound a node refines when it moves anything by more
    than tau_px) and the S-2 detail bound at full weight for a node covering up to A_ref pixels (at least one pixel however small), growing with
    sqrt(area / A_ref) above A_ref = AREA_SHARE W H (S-2: the completion residuals and edge steps under the node,
    not its spread: a smooth gradient spreads but interpolates well); one bound E then steers both."""
    crit = rt.criterion.settings()
    if rt.criterion.name == "thesis":
        alpha = crit["alpha"]
        err = alpha * e_geo + (1.0 - alpha) * e_lumi
    elif rt.criterion.name == "screen":
        cam = rt.camera
        g_px = e_geo * math.hypot(cam.width, cam.height)
        e0 = crit["error_bound"] if crit["target_psnr"] is not None else SCREEN_DEFAULT_BOUND
        geo_term = g_px * max(e0, 1e-12) / crit["pixel_tolerance"]
        area = np.pi * footprint ** 2
        ref = AREA_SHARE * cam.width * cam.height
        cover = np.where(area > ref, np.sqrt(area / ref), 1.0)  # at least one pixel
        err = np.maximum(geo_term, e_detail * cover)
    else:
        raise LodprtError(f"criterion {rt.criterion.name!r}: the oracle has no reference for it")
    return np.where(culled, 0.0, err)


def node_errors_reference(rt, nodes) -> NodeErrors:
    """``node_errors`` in float64 numpy (the tests' reference for the kernel)."""
    if rt.camera is None:
        raise LodprtError("no camera: call set_camera(eye, target, ...) before update()")
    nodes = np.asarray(nodes, np.int64)
    cam = rt.camera
    eye = np.asarray(cam.eye)
    p = rt.node_pos(nodes).astype(np.float64)
    r = rt.radius[nodes]
    # outside the frustum: the bounding sphere is entirely behind one plane
    s = p @ rt.planes[:, :3].T + rt.planes[:, 3]
    outside = (s < -r[:, None]).any(1)
    # T-13 back-facing: every normal in the cone is more than 90 degrees from every direction to the eye
    v = eye - p
    d = np.linalg.norm(v, axis=1)
    vh = v / np.where(d > 0, d, 1.0)[:, None]
    ang = np.arccos(np.clip((vh * rt.axis[nodes]).sum(1), -1.0, 1.0))
    spread = np.arcsin(np.clip(r / np.where(d > 0, d, 1.0), 0.0, 1.0))
    back = (d > r) & (ang > 0.5 * np.pi + rt.half[nodes] + spread)
    culled = outside | back
    # e_geo: the error vector p - p' on screen over the screen diagonal
    c1 = rt.h.children[nodes, 1]  # the vertex the node's collapse removed (a leaf: its own)
    a = rt.positions[np.where(c1 >= 0, rt.h.vertex[np.maximum(c1, 0)], rt.h.vertex[nodes])].astype(np.float64)
    b = a - rt.error_vector[nodes]
    ca = np.c_[a, np.ones(len(a))] @ rt.vp.T
    cb = np.c_[b, np.ones(len(b))] @ rt.vp.T
    tiny = 1e-12
    behind = (ca[:, 3] <= tiny) | (cb[:, 3] <= tiny)
    half_wh = 0.5 * np.array([cam.width, cam.height], np.float64)
    sa = ca[:, :2] / np.where(behind, 1.0, ca[:, 3])[:, None] * half_wh
    sb = cb[:, :2] / np.where(behind, 1.0, cb[:, 3])[:, None] * half_wh
    e_geo = np.where(behind, 1.0, np.linalg.norm(sa - sb, axis=1) / math.hypot(cam.width, cam.height))
    e_geo = np.clip(e_geo, 0.0, 1.0)
    # e_lumi: display-space spread bounded by the interval of the leaves' radiance toward the eye
    y = sh.basis(vh, rt.order)[:, :rt.box_centre.shape[3]]  # 1 (diffuse-only store) or order^2 wide
    hi = np.zeros((len(nodes), 3))
    lo = np.zeros((len(nodes), 3))
    det = np.zeros((len(nodes), 3))
    det_max, total = np.zeros((len(nodes), 3)), np.zeros(3)
    near = rt.lighting.bracket_mask()  # M-5: the samples around the light
    internal = nodes - rt.h.num_vertices
    detail = rt.detail
    for j, slot in zip(rt.used_samples, rt.used_slots):  # each sample in use and the cache slot holding it
        mid = (rt.box_centre[internal, slot].astype(np.float64) * y[:, None, :]).sum(-1)  # (K, C)
        rad = (rt.box_half[internal, slot].astype(np.float64) * np.abs(y)[:, None, :]).sum(-1)
        w = rt.sample_weights[j][None, :]  # C = 1 (grey) broadcasts over R, G, B
        hi += (mid + rad) * w
        lo += (mid - rad) * w
        det += detail[internal, slot].astype(np.float64) * np.abs(w)  # S-2: (K, C) bounds toward any direction
        if near[slot]:
            det_max = np.maximum(det_max, detail[internal, slot].astype(np.float64) * np.ones_like(w))
        total = total + np.abs(w[0])
    if rt.interpolation != "thesis":  # M-5: each sample's detail at full weight (hard shadows between samples)
        det = det_max * total[None, :]
    e_lumi = np.clip((display(hi) - display(lo)).max(1), 0.0, 1.0)
    depth = np.c_[p, np.ones(len(p))] @ rt.vp[3]  # clip w of the node centre
    foot = np.where(depth > r, np.minimum(r * rt.focal_px() / np.where(depth > r, depth, 1.0), 1e9), 1e9)
    e_geo, e_lumi = np.where(culled, 0.0, e_geo), np.where(culled, 0.0, e_lumi)  # culled: no error computed
    foot = np.where(culled, 0.0, foot)
    det = np.where(culled, 0.0, np.minimum(det.max(1), 1.0))
    return NodeErrors(culled, criterion_error(rt, culled, e_geo, e_lumi, foot, det), e_geo, e_lumi, foot, det)
