"""Volumetric self-transfer (patent 4.3, V-1..V-5 of docs/VOLUMES.md), float32 Warp kernels on any device.

The medium is a cell-centred density grid (extinction sigma_t per scene unit) over the box [lo, hi], sampled
trilinearly with clamp to edge inside the box and 0 outside (V-1). Rays are marched in equal steps of at most
``step`` scene units (``n = ceil(t / step - 0.001)`` steps over a length ``t``, at least one), each step's optical depth taken at its
midpoint (V-2); the attenuation of a step is ``exp(-sigma dt)``, so a constant medium is attenuated exactly and
the per-step scattering weights ``T_before (1 - exp(-sigma dt))`` of a ray sum to ``1 - A`` (V-4), never above 1.
Directions: a spherical Fibonacci set ``dirs`` of weight ``4 pi / R`` each, turned per voxel by a random rotation
(``lodprt.kernels.transfer.vertex_rotation``) when asked. Every loop over coefficients is sized from the arrays.
"""

import warp as wp

from lodprt.kernels.sh import bands_of, sh_basis
from lodprt.kernels.transfer import vertex_rotation

wp.set_module_options({"enable_backward": False})

FOUR_PI = 12.566370614359172
#: a ray stops once its transmittance falls below this (what is left could add at most this fraction)
MIN_TRANSMITTANCE = 1.0e-6
#: steps over a length t: ceil(t / step - STEP_SLACK), at least 1 when t > 0 (a length within rounding of a whole
#: number of steps takes that number on every device and in float64)
STEP_SLACK = 1.0e-3


@wp.func
def step_count(length: float, step: float):
    if length <= 0.0:
        return int(0)
    return wp.max(int(wp.ceil(length / step - STEP_SLACK)), 1)


@wp.func
def corner(u: float, n: int):
    # the two cell-centred samples around continuous index u (clamped to the edge) and the weight of the second
    fu = wp.floor(u)
    i0 = int(fu)
    return wp.clamp(i0, 0, n - 1), wp.clamp(i0 + 1, 0, n - 1), u - fu


@wp.func
def inside(x: wp.vec3, lo: wp.vec3, hi: wp.vec3):
    return x[0] >= lo[0] and x[1] >= lo[1] and x[2] >= lo[2] and x[0] <= hi[0] and x[1] <= hi[1] and x[2] <= hi[2]


@wp.func
def density_at(
    density: wp.array3d(dtype=wp.float32),  # In: (X, Y, Z) sigma_t at voxel centres
    lo: wp.vec3,  # In: box minimum corner
    hi: wp.vec3,  # In: box maximum corner
    x: wp.vec3,  # In: point
):
    # V-1: trilinear, clamp to edge, 0 outside the box
    if not inside(x, lo, hi):
        return float(0.0)
    nx = density.shape[0]
    ny = density.shape[1]
    nz = density.shape[2]
    ax, bx, fx = corner((x[0] - lo[0]) / (hi[0] - lo[0]) * float(nx) - 0.5, nx)
    ay, by, fy = corner((x[1] - lo[1]) / (hi[1] - lo[1]) * float(ny) - 0.5, ny)
    az, bz, fz = corner((x[2] - lo[2]) / (hi[2] - lo[2]) * float(nz) - 0.5, nz)
    c00 = density[ax, ay, az] * (1.0 - fz) + density[ax, ay, bz] * fz
    c01 = density[ax, by, az] * (1.0 - fz) + density[ax, by, bz] * fz
    c10 = density[bx, ay, az] * (1.0 - fz) + density[bx, ay, bz] * fz
    c11 = density[bx, by, az] * (1.0 - fz) + density[bx, by, bz] * fz
    c0 = c00 * (1.0 - fy) + c01 * fy
    c1 = c10 * (1.0 - fy) + c11 * fy
    return c0 * (1.0 - fx) + c1 * fx


@wp.func
def box_exit(o: wp.vec3, d: wp.vec3, lo: wp.vec3, hi: wp.vec3):
    # distance D from o (inside the box) along unit d to the box's boundary (slab method); 0 when o is outside
    t = float(1.0e30)
    for a in range(3):
        if d[a] > 0.0:
            t = wp.min(t, (hi[a] - o[a]) / d[a])
        elif d[a] < 0.0:
            t = wp.min(t, (lo[a] - o[a]) / d[a])
    return wp.max(t, 0.0)


@wp.func
def transmittance(
    density: wp.array3d(dtype=wp.float32),
    lo: wp.vec3,
    hi: wp.vec3,
    o: wp.vec3,  # In: start
    d: wp.vec3,  # In: unit direction
    length: float,  # In: path length
    step: float,  # In: largest step
):
    # V-2: A(o -> o + length d) = exp(-sum sigma(midpoint) dt)
    n = step_count(length, step)
    if n < 1:
        return float(1.0)
    dt = length / float(n)
    tau = float(0.0)
    for s in range(n):
        tau = tau + density_at(density, lo, hi, o + (float(s) + 0.5) * dt * d) * dt
    return wp.exp(-tau)


@wp.func
def voxel_centre(v: int, nx: int, ny: int, nz: int, lo: wp.vec3, hi: wp.vec3):
    i = v // (ny * nz)
    j = (v // nz) % ny
    k = v % nz
    return wp.vec3(lo[0] + (float(i) + 0.5) * (hi[0] - lo[0]) / float(nx),
                   lo[1] + (float(j) + 0.5) * (hi[1] - lo[1]) / float(ny),
                   lo[2] + (float(k) + 0.5) * (hi[2] - lo[2]) / float(nz))


@wp.kernel
def segment_transmittance(
    density: wp.array3d(dtype=wp.float32),  # In: (X, Y, Z) sigma_t at voxel centres
    lo: wp.vec3,  # In: box minimum corner
    hi: wp.vec3,  # In: box maximum corner
    step: float,  # In: largest march step (scene units)
    origins: wp.array(dtype=wp.vec3),  # In: (N,) segment starts
    directions: wp.array(dtype=wp.vec3),  # In: (N,) unit directions
    lengths: wp.array(dtype=wp.float32),  # In: (N,) segment lengths; < 0: to the box's boundary (D of V-3)
    out: wp.array(dtype=wp.float32),  # Out: (N,) attenuation A along each segment (V-2)
):
    i = wp.tid()
    o = origins[i]
    d = wp.normalize(directions[i])
    t = lengths[i]
    if t < 0.0:
        t = box_exit(o, d, lo, hi)
    out[i] = transmittance(density, lo, hi, o, d, t, step)


@wp.kernel
def volume_direct(
    density: wp.array3d(dtype=wp.float32),  # In: (X, Y, Z) sigma_t at voxel centres
    lo: wp.vec3,  # In: box minimum corner
    hi: wp.vec3,  # In: box maximum corner
    step: float,  # In: largest march step (scene units)
    dirs: wp.array(dtype=wp.vec3),  # In: (R,) unit directions of weight 4 pi / R
    rotate: int,  # In: 1 to turn the set per voxel
    seed: int,  # In: seed of the per-voxel rotations
    first: int,  # In: voxel of thread 0 (launches of voxel ranges)
    scratch: wp.array2d(dtype=wp.float32),  # Temp: (N, n^2) basis row per voxel
    out: wp.array2d(dtype=wp.float32),  # Out: (N, n^2) += sum_r w A(p -> p + D s_r) y_i(s_r) (V-3, no albedo)
):
    v = first + wp.tid()
    nx = density.shape[0]
    ny = density.shape[1]
    nz = density.shape[2]
    p = voxel_centre(v, nx, ny, nz, lo, hi)
    q = vertex_rotation(seed, v, rotate)
    w = FOUR_PI / float(dirs.shape[0])
    order = bands_of(out.shape[1])
    for r in range(dirs.shape[0]):
        d = wp.quat_rotate(q, dirs[r])
        a = transmittance(density, lo, hi, p, d, box_exit(p, d, lo, hi), step)
        sh_basis(d, order, scratch, v)
        for i in range(out.shape[1]):
            out[v, i] = out[v, i] + w * a * scratch[v, i]


@wp.kernel
def volume_bounce(
    density: wp.array3d(dtype=wp.float32),  # In: (X, Y, Z) sigma_t at voxel centres
    lo: wp.vec3,  # In: box minimum corner
    hi: wp.vec3,  # In: box maximum corner
    step: float,  # In: largest march step (scene units)
    dirs: wp.array(dtype=wp.vec3),  # In: (R,) unit directions of weight 4 pi / R
    rotate: int,  # In: 1 to turn the set per voxel
    seed: int,  # In: seed of the per-voxel rotations
    first: int,  # In: voxel of thread 0 (launches of voxel ranges)
    previous: wp.array4d(dtype=wp.float32),  # In: (X, Y, Z, K) the previous pass' transfer (albedo/4pi included)
    out: wp.array2d(dtype=wp.float32),  # Out: (N, K) += sum_r w sum_steps T_before (1 - e^(-sigma dt)) M^(b-1)(x) (V-4)
):
    v = first + wp.tid()
    nx = density.shape[0]
    ny = density.shape[1]
    nz = density.shape[2]
    p = voxel_centre(v, nx, ny, nz, lo, hi)
    q = vertex_rotation(seed, v, rotate)
    w = FOUR_PI / float(dirs.shape[0])
    kc = previous.shape[3]
    sx = float(nx) / (hi[0] - lo[0])
    sy = float(ny) / (hi[1] - lo[1])
    sz = float(nz) / (hi[2] - lo[2])
    for r in range(dirs.shape[0]):
        d = wp.quat_rotate(q, dirs[r])
        length = box_exit(p, d, lo, hi)
        n = step_count(length, step)
        if n < 1:
            continue
        dt = length / float(n)
        tr = float(1.0)
        for s in range(n):
            x = p + (float(s) + 0.5) * dt * d
            att = wp.exp(-density_at(density, lo, hi, x) * dt)
            g = w * tr * (1.0 - att)  # V-4: light scattered at this step toward p, attenuated on the way
            tr = tr * att
            ax, bx, fx = corner((x[0] - lo[0]) * sx - 0.5, nx)
            ay, by, fy = corner((x[1] - lo[1]) * sy - 0.5, ny)
            az, bz, fz = corner((x[2] - lo[2]) * sz - 0.5, nz)
            for k in range(kc):
                c00 = previous[ax, ay, az, k] * (1.0 - fz) + previous[ax, ay, bz, k] * fz
                c01 = previous[ax, by, az, k] * (1.0 - fz) + previous[ax, by, bz, k] * fz
                c10 = previous[bx, ay, az, k] * (1.0 - fz) + previous[bx, ay, bz, k] * fz
                c11 = previous[bx, by, az, k] * (1.0 - fz) + previous[bx, by, bz, k] * fz
                c0 = c00 * (1.0 - fy) + c01 * fy
                c1 = c10 * (1.0 - fy) + c11 * fy
                out[v, k] = out[v, k] + g * (c0 * (1.0 - fx) + c1 * fx)
            if tr < MIN_TRANSMITTANCE:
                break
