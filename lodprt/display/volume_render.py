"""Pictures of relit volumes (patent 4.3; V-7 in docs/VOLUMES.md): ray marching with front-to-back alpha
compositing in a moderngl fragment shader over two 3-D textures, the density sigma_t and the relit source
radiance J (:func:`lodprt.runtime.volume_relight.source_radiance`).

Per pixel the view ray is clipped to the box and marched in ``n = ceil(length / step)`` equal steps; a step at
midpoint x adds ``T (1 - exp(-sigma(x) dt)) J(x)`` to the colour and multiplies the transmittance T by
``exp(-sigma(x) dt)`` (V-7, the same step weights as the bake's V-4); the result is composited over the background,
``C + T background``, with alpha ``1 - T``. Both textures are sampled cell-centred, trilinear, clamp to edge (V-1),
interpolated in the shader from ``texelFetch`` in float32 (the fixed-function filter of some drivers, llvmpipe's,
keeps only 8 bits of the weights).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from lodprt.display.render import check_size, create_context, tone_map
from lodprt.errors import LodprtError
from lodprt.runtime.camera import look_at, perspective
from lodprt.runtime.volume_relight import source_radiance

#: most march steps per pixel (longer rays take longer steps)
MAX_STEPS = 4096

_VERTEX = """
#version 330
in vec2 in_pos;
void main() { gl_Position = vec4(in_pos, 0.0, 1.0); }
"""

_FRAGMENT = """
#version 330
uniform mat3 ray_basis;  // columns: right tan(fov/2) aspect, up tan(fov/2), forward
uniform vec3 eye;
uniform vec3 lo;
uniform vec3 hi;
uniform vec2 size;
uniform float step_len;
uniform vec3 background;
uniform sampler3D density;
uniform sampler3D source;
out vec4 f_col;

vec4 trilinear(sampler3D tex, vec3 x) {  // V-1: cell-centred, clamp to edge
    ivec3 n = textureSize(tex, 0);
    vec3 u = (x - lo) / (hi - lo) * vec3(n) - 0.5;
    vec3 f0 = floor(u);
    vec3 f = u - f0;
    ivec3 a = clamp(ivec3(f0), ivec3(0), n - 1);
    ivec3 b = clamp(ivec3(f0) + 1, ivec3(0), n - 1);
    vec4 c00 = mix(texelFetch(tex, ivec3(a.x, a.y, a.z), 0), texelFetch(tex, ivec3(a.x, a.y, b.z), 0), f.z);
    vec4 c01 = mix(texelFetch(tex, ivec3(a.x, b.y, a.z), 0), texelFetch(tex, ivec3(a.x, b.y, b.z), 0), f.z);
    vec4 c10 = mix(texelFetch(tex, ivec3(b.x, a.y, a.z), 0), texelFetch(tex, ivec3(b.x, a.y, b.z), 0), f.z);
    vec4 c11 = mix(texelFetch(tex, ivec3(b.x, b.y, a.z), 0), texelFetch(tex, ivec3(b.x, b.y, b.z), 0), f.z);
    return mix(mix(c00, c01, f.y), mix(c10, c11, f.y), f.x);
}

void main() {
    vec2 ndc = gl_FragCoord.xy / size * 2.0 - 1.0;
    vec3 d = normalize(ray_basis * vec3(ndc, 1.0));
    vec3 inv = 1.0 / d;
    vec3 ta = (lo - eye) * inv;
    vec3 tb = (hi - eye) * inv;
    vec3 tmin = min(ta, tb);
    vec3 tmax = max(ta, tb);
    float t0 = max(max(max(tmin.x, tmin.y), tmin.z), 0.0);
    float t1 = min(min(tmax.x, tmax.y), tmax.z);
    vec3 col = vec3(0.0);
    float tr = 1.0;
    if (t1 > t0) {
        int n = clamp(int(ceil((t1 - t0) / step_len - 0.001)), 1, MAX_STEPS);  // as kernels/volume.py step_count
        float dt = (t1 - t0) / float(n);
        for (int s = 0; s < n; ++s) {
            vec3 x = eye + (t0 + (float(s) + 0.5) * dt) * d;
            float a = exp(-trilinear(density, x).r * dt);
            col += tr * (1.0 - a) * trilinear(source, x).rgb;  // V-7
            tr *= a;
            if (tr < 1e-6) break;
        }
    }
    f_col = vec4(col + tr * background, 1.0 - tr);
}
""".replace("MAX_STEPS", str(MAX_STEPS))


def camera(eye, target, up, fov: float, size, lo, hi) -> np.ndarray:
    """The view-projection matrix (4, 4) float64 of the camera (the convention of ``lodprt.runtime.camera``);
    near and far bracket the box."""
    eye = np.asarray(eye, np.float64)
    corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
    dist = np.linalg.norm(corners - eye, axis=1)
    far = float(dist.max()) * 1.01 + 1e-6
    near = max(far * 1e-4, 1e-6)
    width, height = size
    return perspective(fov, width / height, near, far) @ look_at(eye, target, up)


def ray_basis(eye, target, up, fov: float, size) -> np.ndarray:
    """(3, 3) columns right tan(fov/2) aspect, up tan(fov/2), forward: the world direction of the ray through
    normalised device coordinates (x, y) is ``basis @ (x, y, 1)``, the rays of :func:`camera`'s matrix."""
    view = look_at(eye, target, up)
    t = np.tan(np.radians(fov) / 2)
    width, height = size
    return np.stack([view[0, :3] * t * width / height, view[1, :3] * t, -view[2, :3]], axis=1)


def _texture(ctx, data: np.ndarray, components: int):
    """A float32 3-D texture of (X, Y, Z[, C]) data, x fastest as OpenGL stores it."""
    arr = np.ascontiguousarray(np.asarray(data, np.float32).reshape(data.shape[:3] + (components,)).transpose(2, 1, 0, 3))
    tex = ctx.texture3d(data.shape[:3], components, arr.tobytes(), dtype="f4")
    tex.repeat_x = tex.repeat_y = tex.repeat_z = False
    return tex


def march(density, source, lo, hi, *, eye, target=None, up=(0.0, 1.0, 0.0), fov: float = 40.0, size=(800, 600),
          step: float | None = None, background=(0.0, 0.0, 0.0)) -> tuple[np.ndarray, np.ndarray]:
    """Ray-march a medium on the GPU (V-7): density (X, Y, Z) sigma_t, source (X, Y, Z, 3) radiance J over the box
    [lo, hi] -> (linear radiance (H, W, 3) float32 composited over ``background``, alpha (H, W) float32), first row
    on top. ``step``: largest march step in scene units (default half the smallest voxel edge)."""
    dens = np.asarray(density, np.float32)
    src = np.asarray(source, np.float32)
    lo, hi = np.asarray(lo, np.float64), np.asarray(hi, np.float64)
    if dens.ndim != 3 or src.shape != dens.shape + (3,):
        raise LodprtError(f"render volume: density {dens.shape} and source {src.shape} must be (X, Y, Z) and (X, Y, Z, 3)")
    step = 0.5 * float(((hi - lo) / np.array(dens.shape)).min()) if step is None else float(step)
    if not np.isfinite(step) or step <= 0:
        raise LodprtError(f"render volume: step {step!r} must be a positive number of scene units")
    target = (lo + hi) / 2 if target is None else np.asarray(target, np.float64)
    ctx = create_context()
    try:
        width, height = check_size(size, ctx)
        basis = ray_basis(eye, target, up, fov, (width, height))
        prog = ctx.program(vertex_shader=_VERTEX, fragment_shader=_FRAGMENT)
        prog["ray_basis"].write(basis.T.astype(np.float32).tobytes())  # column-major
        for name, value in (("eye", eye), ("lo", lo), ("hi", hi), ("background", background)):
            prog[name].value = tuple(float(x) for x in value)
        prog["size"].value = (float(width), float(height))
        prog["step_len"].value = step
        prog["density"].value = 0
        prog["source"].value = 1
        _texture(ctx, dens, 1).use(0)
        _texture(ctx, src, 3).use(1)
        vbo = ctx.buffer(np.array([-1, -1, 3, -1, -1, 3], np.float32).tobytes())
        vao = ctx.vertex_array(prog, [(vbo, "2f", "in_pos")])
        fbo = ctx.framebuffer(color_attachments=[ctx.renderbuffer((width, height), components=4, dtype="f4")])
        fbo.use()
        fbo.clear(0.0, 0.0, 0.0, 0.0)
        vao.render()
        img = np.frombuffer(fbo.read(components=4, dtype="f4"), np.float32).reshape(height, width, 4)[::-1]
        return img[..., :3].copy(), img[..., 3].copy()
    finally:
        ctx.release()


def render_volume(store, lighting, *, eye, target=None, up=(0.0, 1.0, 0.0), fov: float = 40.0, size=(800, 600),
                  white: float | None = None, step: float | None = None, background=(0.0, 0.0, 0.0)):
    """A volume store relit by ``lighting`` (3, n^2) and drawn from ``eye``: (image (H, W, 3) uint8, linear
    radiance (H, W, 3), alpha (H, W)). ``white``: radiance shown as white (default the 99th percentile of the
    pixels the medium covers); tone mapping of :func:`lodprt.display.render.tone_map`."""
    vol = store.volume()
    src = source_radiance(store.transfer(), lighting)
    if step is None:
        step = float(store.attrs.get("step") or 0.0) or None  # the bake's own march step
    rgb, alpha = march(vol.density, src, vol.lo, vol.hi, eye=eye, target=target, up=up, fov=fov, size=size,
                       step=step, background=background)
    if white is None:
        seen = rgb[alpha > 0.01]
        seen = seen[seen > 0]
        white = float(np.percentile(seen, 99)) if seen.size else 1.0
    img = (np.round(tone_map(rgb, white) * 255)).astype(np.uint8)
    return img, rgb, alpha


def save_png(path, image) -> Path:
    """Write an (H, W, 3) uint8 image as PNG."""
    import matplotlib.image

    path = Path(path)
    matplotlib.image.imsave(path, image)
    return path
