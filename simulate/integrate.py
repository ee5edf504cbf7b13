"""Time integration of rigid clumps: velocity Verlet for translation, angular momentum and
quaternion for rotation.

One step of length dt (kick-drift-kick, as LIGGGHTS' ``nve`` integrators):

    v    += (F/m + g) dt/2;   L += T dt/2 (+ capped rolling torque, see contact.rolling)
    x    += v dt
    q    <- exp(w(t + dt/2) dt / 2) q  with w = R diag(1/I) R^T L (principal frame), the
            mid-step w from the torque-free Euler equations dw/dt = -I^-1 (w x L) (second
            order; the free rotation of an asymmetric top follows the full inertia tensor)
    ... contact forces at the new positions ...
    v    += (F/m + g) dt/2;   L += T dt/2 (+ capped rolling torque)

Within a chunk of steps the closing half kick of one step and the opening half kick of the next
are applied as one kick over dt (leapfrog form of the same scheme). The angular momentum L is
kept in the world frame, so a torque-free body conserves it exactly; the inertia tensor enters
only through w = R I_p^-1 R^T L. Quaternions are (w, x, y, z), rotating principal-frame
vectors into the world frame.

References
----------
Allen, M. P., Tildesley, D. J. (2017). Computer Simulation of Liquids, 2nd ed., sec. 3.3.
Omelyan, I. P. (1998). On the numerical integration of motion for rigid polyatomics: the
modified quaternion approach. Comput. Phys. 12, 97-103.
Stronge, W. J. (2000). Impact Mechanics. Cambridge University Press.
"""

from __future__ import annotations

import math

import numpy as np

from demcal.simulate._jit import evaluator, kernel, loop_kernel
from demcal.simulate.contact.rolling import KICK_ELASTIC, KICK_RELATIVE, cap_rolling_impulse


@evaluator
def quat_to_matrix(q, b, R):
    """Write the rotation matrix of unit quaternion ``q[b]`` into ``R[b]``."""
    w = q[b, 0]
    x = q[b, 1]
    y = q[b, 2]
    z = q[b, 3]
    R[b, 0, 0] = 1.0 - 2.0 * (y * y + z * z)
    R[b, 0, 1] = 2.0 * (x * y - w * z)
    R[b, 0, 2] = 2.0 * (x * z + w * y)
    R[b, 1, 0] = 2.0 * (x * y + w * z)
    R[b, 1, 1] = 1.0 - 2.0 * (x * x + z * z)
    R[b, 1, 2] = 2.0 * (y * z - w * x)
    R[b, 2, 0] = 2.0 * (x * z - w * y)
    R[b, 2, 1] = 2.0 * (y * z + w * x)
    R[b, 2, 2] = 1.0 - 2.0 * (x * x + y * y)


@evaluator
def apply_inverse_inertia(R, b, inv_i, ax, ay, az):
    """R diag(inv_i) R^T a: a world-frame angular momentum (or torque) to angular velocity."""
    px = R[b, 0, 0] * ax + R[b, 1, 0] * ay + R[b, 2, 0] * az
    py = R[b, 0, 1] * ax + R[b, 1, 1] * ay + R[b, 2, 1] * az
    pz = R[b, 0, 2] * ax + R[b, 1, 2] * ay + R[b, 2, 2] * az
    px *= inv_i[b, 0]
    py *= inv_i[b, 1]
    pz *= inv_i[b, 2]
    return (R[b, 0, 0] * px + R[b, 0, 1] * py + R[b, 0, 2] * pz,
            R[b, 1, 0] * px + R[b, 1, 1] * py + R[b, 1, 2] * pz,
            R[b, 2, 0] * px + R[b, 2, 1] * py + R[b, 2, 2] * pz)


@evaluator
def damping_inverse_mass(R, inv_i, inv_m, count, b, ax, ay, az, nx, ny, nz):
    """Inverse of the mass a normal dashpot of body ``b`` damps with, when the body shares it
    among its ``count[b]`` touching contacts (``contact_effective_mass``): the larger of
    count / m and the rigid-body inverse mass at the contact along ``n``,
    1/m + (a x n) . I^-1 (a x n), for the lever ``a`` from the centre of mass [1/kg].

    One contact alone then damps its own effective mass, so an off-centre impact rebounds at
    the contact restitution as rigid-body impact theory has it (Stronge 2000, ch. 3); n equal
    contacts of a flat landing (levers cancelling) damp m / n each, i.e. as one contact of n
    times the stiffness.
    """
    cx = ay * nz - az * ny
    cy = az * nx - ax * nz
    cz = ax * ny - ay * nx
    wx, wy, wz = apply_inverse_inertia(R, b, inv_i, cx, cy, cz)
    return max(inv_m[b] + cx * wx + cy * wy + cz * wz, inv_m[b] * count[b])


@evaluator
def apply_inertia(R, b, inv_i, wx, wy, wz):
    """R diag(1 / inv_i) R^T w: a world-frame angular velocity to angular momentum (an axis of
    zero inverse inertia holds no angular velocity and gives none)."""
    px = R[b, 0, 0] * wx + R[b, 1, 0] * wy + R[b, 2, 0] * wz
    py = R[b, 0, 1] * wx + R[b, 1, 1] * wy + R[b, 2, 1] * wz
    pz = R[b, 0, 2] * wx + R[b, 1, 2] * wy + R[b, 2, 2] * wz
    px = px / inv_i[b, 0] if inv_i[b, 0] > 0.0 else 0.0
    py = py / inv_i[b, 1] if inv_i[b, 1] > 0.0 else 0.0
    pz = pz / inv_i[b, 2] if inv_i[b, 2] > 0.0 else 0.0
    return (R[b, 0, 0] * px + R[b, 0, 1] * py + R[b, 0, 2] * pz,
            R[b, 1, 0] * px + R[b, 1, 1] * py + R[b, 1, 2] * pz,
            R[b, 2, 0] * px + R[b, 2, 1] * py + R[b, 2, 2] * pz)


@evaluator
def pair_rolling_scale(R, inv_i, bi, bj, tx, ty, tz, magnitude, wrx, wry, wrz, dt):
    """Fraction in [0, 1] of a pair rolling torque (``t`` on body i, ``-t`` on body j, of length
    ``magnitude``) to apply over ``dt`` so that its impulse does not reverse the relative angular
    velocity ``w_r = w_i - w_j``; both bodies receive the same fraction, so angular momentum is
    kept."""
    # the impulse changes w_r by at most |t| dt (max 1/I_i + max 1/I_j): usually far less than w_r
    bound = magnitude * dt * (max(inv_i[bi, 0], inv_i[bi, 1], inv_i[bi, 2])
                              + max(inv_i[bj, 0], inv_i[bj, 1], inv_i[bj, 2]))
    if bound * bound < wrx * wrx + wry * wry + wrz * wrz:
        return 1.0
    return _pair_rolling_scale_exact(R, inv_i, bi, bj, tx * dt, ty * dt, tz * dt, wrx, wry, wrz)


@loop_kernel
def _pair_rolling_scale_exact(R, inv_i, bi, bj, jx, jy, jz, wrx, wry, wrz):
    """``pair_rolling_scale`` for an impulse ``j`` that may reverse ``w_r`` (rare, not inlined)."""
    dix, diy, diz = apply_inverse_inertia(R, bi, inv_i, jx, jy, jz)
    djx, djy, djz = apply_inverse_inertia(R, bj, inv_i, jx, jy, jz)
    return cap_rolling_impulse(wrx, wry, wrz, dix + djx, diy + djy, diz + djz)


@evaluator
def rotate_quat(q0, q1, q2, q3, wx, wy, wz, dt):
    """exp(w dt / 2) * q for a world-frame angular velocity ``w`` [rad/s], normalised."""
    w2 = wx * wx + wy * wy + wz * wz
    x2 = 0.25 * w2 * dt * dt  # (half angle)^2
    if x2 < 1e-4:
        # Taylor series of cos(x) and sin(x)/x, exact to double precision for x < 0.01
        c = 1.0 - x2 * (0.5 - x2 * (1.0 / 24.0 - x2 / 720.0))
        s = 0.5 * dt * (1.0 - x2 * (1.0 / 6.0 - x2 * (1.0 / 120.0 - x2 / 5040.0)))
    else:
        wmag = math.sqrt(w2)
        c = math.cos(0.5 * wmag * dt)
        s = math.sin(0.5 * wmag * dt) / wmag
    a0 = c
    a1 = s * wx
    a2 = s * wy
    a3 = s * wz
    r0 = a0 * q0 - a1 * q1 - a2 * q2 - a3 * q3
    r1 = a0 * q1 + a1 * q0 + a2 * q3 - a3 * q2
    r2 = a0 * q2 - a1 * q3 + a2 * q0 + a3 * q1
    r3 = a0 * q3 + a1 * q2 - a2 * q1 + a3 * q0
    inv = 1.0 / math.sqrt(r0 * r0 + r1 * r1 + r2 * r2 + r3 * r3)
    return r0 * inv, r1 * inv, r2 * inv, r3 * inv


@evaluator
def half_kick(b, h, gx, gy, gz, bv, bL, bw, bR, bf, bt, brm, brv, brn, binvm, binvi, mode):
    """Kick of body ``b`` over ``h`` (dt/2, or dt for two merged half kicks): forces, torques,
    then the rolling torque (see ``simulate.contact.rolling``).

    ``brm[b]`` is the summed magnitude of the body's rolling torques. With the EDEM conventions
    (``mode`` ``KICK_DIRECTIONAL``) the torque is ``brm[b]`` against the unit angular velocity
    after the other torques; with the LIGGGHTS convention (``KICK_RELATIVE``) it is the vector
    ``brv[b]`` summed over the body's wall contacts (particle pairs apply theirs as ordinary
    torques, in ``bt``), ``brm[b]`` their magnitudes and ``brn[b]`` their normals weighted by
    the magnitudes. If the resistance ``brm[b]`` over ``h`` could absorb the body's rolling
    angular momentum, the rolling stops (the torque acts as a static constraint up to its
    magnitude); the twist about the normal is kept when every wall contact of the body shares
    that normal (LIGGGHTS convention). Otherwise the torque acts in full, scaled down only so
    that it never reverses the spin about the current axis. With the spring-dashpot
    model (``KICK_ELASTIC``) ``brv[b]`` is an ordinary torque, applied in full (a spring must be
    free to turn the body back), and ``brm[b]`` (its limit) is not used. Updates v, L and w of
    the body.
    """
    im = binvm[b]
    bv[b, 0] += (bf[b, 0] * im + gx) * h
    bv[b, 1] += (bf[b, 1] * im + gy) * h
    bv[b, 2] += (bf[b, 2] * im + gz) * h
    lx = bL[b, 0] + bt[b, 0] * h
    ly = bL[b, 1] + bt[b, 1] * h
    lz = bL[b, 2] + bt[b, 2] * h
    m = brm[b]
    if mode == KICK_ELASTIC:
        lx += brv[b, 0] * h
        ly += brv[b, 1] * h
        lz += brv[b, 2] * h
        wx, wy, wz = apply_inverse_inertia(bR, b, binvi, lx, ly, lz)
    else:
        wx, wy, wz = apply_inverse_inertia(bR, b, binvi, lx, ly, lz)
        stops = False
        if m > 0.0:
            stops, lx, ly, lz, wx, wy, wz = rolling_stop(b, m, m * h, lx, ly, lz, wx, wy, wz, bR, binvi,
                                                         brn, mode)
        if not stops:
            lx, ly, lz, wx, wy, wz = _rolling_kick(b, h, m, lx, ly, lz, wx, wy, wz, bR, binvi, brv, mode)
    bL[b, 0] = lx
    bL[b, 1] = ly
    bL[b, 2] = lz
    bw[b, 0] = wx
    bw[b, 1] = wy
    bw[b, 2] = wz


@evaluator
def rolling_stop(b, m, impulse, lx, ly, lz, wx, wy, wz, bR, binvi, brn, mode):
    """The static stop of the rolling of body ``b``.

    ``l`` and ``w`` are the body's angular momentum and velocity after its other torques, ``m``
    its summed rolling resistance and ``impulse`` that over the half step. The rolling part of
    the rotation is all of it, except with the LIGGGHTS convention when every wall contact of
    the body shares one normal (``brn[b]``, the normals weighted by their magnitudes, is then
    ``m`` long): the spin about that normal is twist, which the rolling torque does not resist,
    and is kept.

    Returns
    -------
    (stops, lx, ly, lz, wx, wy, wz)
        Whether ``impulse`` absorbs the angular momentum of the rolling part; the angular
        momentum and velocity that remain (the twist, or zero), or ``l`` and ``w`` unchanged.
    """
    tx = 0.0
    ty = 0.0
    tz = 0.0
    twist = False
    if mode == KICK_RELATIVE:
        nx = brn[b, 0]
        ny = brn[b, 1]
        nz = brn[b, 2]
        n2 = nx * nx + ny * ny + nz * nz
        if n2 > 0.0 and n2 >= ((1.0 - 1e-9) * m) ** 2:
            wn = (wx * nx + wy * ny + wz * nz) / n2
            tx = wn * nx
            ty = wn * ny
            tz = wn * nz
            twist = True
    rx = wx - tx
    ry = wy - ty
    rz = wz - tz
    # |I w_r| >= |w_r| / max(1/I): most bodies are rejected here without the inertia product
    inv_max = max(binvi[b, 0], binvi[b, 1], binvi[b, 2])
    if rx * rx + ry * ry + rz * rz > (impulse * inv_max) ** 2:
        return False, lx, ly, lz, wx, wy, wz
    if twist:
        kx, ky, kz = apply_inertia(bR, b, binvi, rx, ry, rz)
    else:
        kx, ky, kz = lx, ly, lz
    if kx * kx + ky * ky + kz * kz <= impulse * impulse:
        return True, lx - kx, ly - ky, lz - kz, tx, ty, tz
    return False, lx, ly, lz, wx, wy, wz


@evaluator
def _rolling_kick(b, h, m, lx, ly, lz, wx, wy, wz, bR, binvi, brv, mode):
    """The rolling torque of body ``b`` over ``h`` when it does not stop the rolling: the wall
    torque vector (LIGGGHTS convention) or ``m`` against the spin (EDEM), capped so that it
    never reverses the spin about the current axis. Returns the new L and w."""
    tx = 0.0
    ty = 0.0
    tz = 0.0
    if mode == KICK_RELATIVE:
        tx = brv[b, 0]
        ty = brv[b, 1]
        tz = brv[b, 2]
    elif m > 0.0:
        wmag = math.sqrt(wx * wx + wy * wy + wz * wz)
        if wmag > 0.0:
            c = m / wmag
            tx = -c * wx
            ty = -c * wy
            tz = -c * wz
    if tx != 0.0 or ty != 0.0 or tz != 0.0:
        dwx, dwy, dwz = apply_inverse_inertia(bR, b, binvi, tx * h, ty * h, tz * h)
        s = cap_rolling_impulse(wx, wy, wz, dwx, dwy, dwz)
        lx += s * tx * h
        ly += s * ty * h
        lz += s * tz * h
        wx += s * dwx
        wy += s * dwy
        wz += s * dwz
    return lx, ly, lz, wx, wy, wz


@evaluator
def drift(b, dt, bx, bv, bq, bL, bw, bR, binvi):
    """Move body ``b`` by v dt and turn it by the mid-step angular velocity; refresh R and w.

    The mid-step angular velocity follows from the torque-free Euler equations in the world
    frame, dw/dt = -I^-1 (w x L): w(t + dt/2) = w - dt/2 I^-1 (w x L) (second order).
    """
    bx[b, 0] += bv[b, 0] * dt
    bx[b, 1] += bv[b, 1] * dt
    bx[b, 2] += bv[b, 2] * dt
    lx = bL[b, 0]
    ly = bL[b, 1]
    lz = bL[b, 2]
    if lx != 0.0 or ly != 0.0 or lz != 0.0:
        wx = bw[b, 0]
        wy = bw[b, 1]
        wz = bw[b, 2]
        ax, ay, az = apply_inverse_inertia(bR, b, binvi, wy * lz - wz * ly, wz * lx - wx * lz,
                                           wx * ly - wy * lx)
        h = 0.5 * dt
        n0, n1, n2, n3 = rotate_quat(bq[b, 0], bq[b, 1], bq[b, 2], bq[b, 3],
                                     wx - h * ax, wy - h * ay, wz - h * az, dt)
        bq[b, 0] = n0
        bq[b, 1] = n1
        bq[b, 2] = n2
        bq[b, 3] = n3
        quat_to_matrix(bq, b, bR)
        wx, wy, wz = apply_inverse_inertia(bR, b, binvi, lx, ly, lz)
        bw[b, 0] = wx
        bw[b, 1] = wy
        bw[b, 2] = wz


@kernel
def refresh_rotation(n_bodies, bq, bL, bw, bR, binvi):
    """Normalise quaternions, rebuild rotation matrices and w = R I^-1 R^T L of every body."""
    for b in range(n_bodies):
        n = math.sqrt(bq[b, 0] ** 2 + bq[b, 1] ** 2 + bq[b, 2] ** 2 + bq[b, 3] ** 2)
        for a in range(4):
            bq[b, a] /= n
        quat_to_matrix(bq, b, bR)
        wx, wy, wz = apply_inverse_inertia(bR, b, binvi, bL[b, 0], bL[b, 1], bL[b, 2])
        bw[b, 0] = wx
        bw[b, 1] = wy
        bw[b, 2] = wz


def quat_from_matrix(R) -> np.ndarray:
    """Unit quaternion (w, x, y, z) of a rotation matrix (Shepperd's method)."""
    R = np.asarray(R, dtype=float)
    tr = np.trace(R)
    if tr > 0:
        s = 2.0 * np.sqrt(tr + 1.0)
        q = [0.25 * s, (R[2, 1] - R[1, 2]) / s, (R[0, 2] - R[2, 0]) / s, (R[1, 0] - R[0, 1]) / s]
    elif R[0, 0] > R[1, 1] and R[0, 0] > R[2, 2]:
        s = 2.0 * np.sqrt(1.0 + R[0, 0] - R[1, 1] - R[2, 2])
        q = [(R[2, 1] - R[1, 2]) / s, 0.25 * s, (R[0, 1] + R[1, 0]) / s, (R[0, 2] + R[2, 0]) / s]
    elif R[1, 1] > R[2, 2]:
        s = 2.0 * np.sqrt(1.0 + R[1, 1] - R[0, 0] - R[2, 2])
        q = [(R[0, 2] - R[2, 0]) / s, (R[0, 1] + R[1, 0]) / s, 0.25 * s, (R[1, 2] + R[2, 1]) / s]
    else:
        s = 2.0 * np.sqrt(1.0 + R[2, 2] - R[0, 0] - R[1, 1])
        q = [(R[1, 0] - R[0, 1]) / s, (R[0, 2] + R[2, 0]) / s, (R[1, 2] + R[2, 1]) / s, 0.25 * s]
    q = np.asarray(q)
    return q / np.linalg.norm(q)


def matrix_from_quat(q) -> np.ndarray:
    """Rotation matrix of quaternion (w, x, y, z) (normalised first)."""
    w, x, y, z = np.asarray(q, dtype=float) / np.linalg.norm(q)
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                     [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                     [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


def quat_multiply(a, b) -> np.ndarray:
    """Hamilton product a * b of quaternions (w, x, y, z)."""
    a0, a1, a2, a3 = a
    b0, b1, b2, b3 = b
    return np.array([a0 * b0 - a1 * b1 - a2 * b2 - a3 * b3,
                     a0 * b1 + a1 * b0 + a2 * b3 - a3 * b2,
                     a0 * b2 - a1 * b3 + a2 * b0 + a3 * b1,
                     a0 * b3 + a1 * b2 - a2 * b1 + a3 * b0])


def random_quaternions(rng: np.random.Generator, n: int) -> np.ndarray:
    """``n`` uniformly distributed unit quaternions (Shoemake 1992, Graphics Gems III)."""
    return quaternions_from_uniforms(rng.random((3, n)).T)


def quaternions_from_uniforms(u) -> np.ndarray:
    """Unit quaternions from rows of three uniform numbers in [0, 1) (Shoemake 1992): uniformly
    distributed for uniform rows."""
    u1, u2, u3 = np.asarray(u, dtype=float).T
    a, b = np.sqrt(1.0 - u1), np.sqrt(u1)
    q = np.empty((u1.size, 4))
    q[:, 0] = a * np.sin(2 * np.pi * u2)
    q[:, 1] = a * np.cos(2 * np.pi * u2)
    q[:, 2] = b * np.sin(2 * np.pi * u3)
    q[:, 3] = b * np.cos(2 * np.pi * u3)
    return q


def row_norms(a) -> np.ndarray:
    """Euclidean norm of each row of ``a`` (n, k), to the bits of ``numpy.linalg.norm`` of that
    row alone: the square root of its dot product with itself, taken on a contiguous copy (numpy
    may sum a strided row in another order)."""
    a = np.ascontiguousarray(a, dtype=float)
    return np.sqrt(np.array([row.dot(row) for row in a]))


def matrices_from_quats(q) -> np.ndarray:
    """``matrix_from_quat`` of each row of ``q`` (n, 4), to the same bits: each row's norm is
    taken as ``numpy.linalg.norm`` takes it (``row_norms``), the rest is elementwise."""
    q = np.asarray(q, dtype=float)
    norm = row_norms(q)
    w, x, y, z = (q / norm[:, None]).T
    R = np.empty((q.shape[0], 3, 3))
    R[:, 0, 0], R[:, 0, 1], R[:, 0, 2] = 1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)
    R[:, 1, 0], R[:, 1, 1], R[:, 1, 2] = 2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)
    R[:, 2, 0], R[:, 2, 1], R[:, 2, 2] = 2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)
    return R


def axis_angle_quat(axis, angle: float) -> np.ndarray:
    """Quaternion of a rotation by ``angle`` [rad] about ``axis``."""
    axis = np.asarray(axis, dtype=float)
    axis = axis / np.linalg.norm(axis)
    return np.concatenate([[np.cos(angle / 2.0)], np.sin(angle / 2.0) * axis])
