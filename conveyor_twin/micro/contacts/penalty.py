"""The penalty model (Rideout, Stein): a spring-damper and Coulomb friction per contact point.

``f_n = max(0, k d - c u_n)`` and a Coulomb friction force ``min(mu f_n, |u_t| / (k_t dt))``
against the sliding (the second term stops it within one substep without reversing it); no
position correction. The forces accumulate into force arrays; the kernel turns them into
velocities.
"""

from numba import njit

from conveyor_twin.micro.contacts.response import friction_coefficient
from conveyor_twin.micro.contacts.tables import (A_CONTACT_FRICTION, A_DAMPER, A_SPRING, CT_BVX,
                                                 CT_BVY, CT_BW, CT_DEPTH, CT_MU_K, CT_MU_S,
                                                 CT_NX, CT_NY, CT_RAX, CT_RAY, CT_RBX, CT_RBY,
                                                 CT_V_T, MP_DAMPING, MP_DT, MP_STIFFNESS,
                                                 MP_TRACK)
from conveyor_twin.micro.state import PT_INV_INERTIA, PT_INV_MASS


@njit(cache=True)
def penalty_force(a, b, nx, ny, spring, friction):
    """Return the contact force on A [N] and the powers of its spring, damper and friction [W].

    :param a: body A, ``(vx, vy, w, im, ii, rx, ry)``: velocity [m/s], angular velocity
        [rad/s], inverse mass [1/kg] (0: kinematic), inverse inertia, contact point relative
        to its centre (or pivot) [m]. ``b``: body B, the same.
    :param nx: unit normal pointing to A, with ``ny``.
    :param spring: ``(depth, k, c, dt)``: penetration [m], spring [N/m], damper [N s/m],
        substep [s]. ``friction``: ``(mu_s, mu_k, v_t)``, the friction law.
    :return: (f_x, f_y, p_spring, p_damper, p_friction); B feels the opposite force.
    """
    vax, vay, wa, ima, iia, rax, ray = a
    vbx, vby, wb, imb, iib, rbx, rby = b
    depth, k, c, dt = spring
    mu_s, mu_k, v_t = friction
    ux = (vax - wa * ray) - (vbx - wb * rby)
    uy = (vay + wa * rax) - (vby + wb * rbx)
    un = ux * nx + uy * ny
    fs = k * depth
    fn = fs - c * un
    if fn <= 0.0:
        return 0.0, 0.0, abs(fs * un), 0.0, 0.0
    tx = -ny
    ty = nx
    ut = ux * tx + uy * ty
    rta = rax * ty - ray * tx
    rtb = rbx * ty - rby * tx
    kt = ima + imb + iia * rta * rta + iib * rtb * rtb
    ft = friction_coefficient(mu_s, mu_k, v_t, abs(ut)) * fn
    stick = abs(ut) / (kt * dt)
    if stick < ft:
        ft = stick
    if ut > 0.0:
        ft = -ft
    return (fn * nx + ft * tx, fn * ny + ft * ty, abs(fs * un), abs(c * un * un),
            abs(ft * ut))


@njit(cache=True)
def penalty_forces(nc, ct, cidx, ptype, vx, vy, wz, fx, fy, tz, pt, mp, acc):
    """Accumulate the penalty spring-damper and friction forces of the contacts [N, N m]."""
    track = mp[MP_TRACK] != 0.0
    dt = mp[MP_DT]
    for c in range(nc):
        a = cidx[c, 0]
        b = cidx[c, 1]
        ta = ptype[a]
        if b >= 0:
            tb = ptype[b]
            bvx = vx[b]
            bvy = vy[b]
            bw = wz[b]
            imb = pt[tb, PT_INV_MASS]
            iib = pt[tb, PT_INV_INERTIA]
        else:
            bvx = ct[c, CT_BVX]
            bvy = ct[c, CT_BVY]
            bw = ct[c, CT_BW]
            imb = 0.0
            iib = 0.0
        rax = ct[c, CT_RAX]
        ray = ct[c, CT_RAY]
        rbx = ct[c, CT_RBX]
        rby = ct[c, CT_RBY]
        fcx, fcy, ps, pd, pf = penalty_force(
            (vx[a], vy[a], wz[a], pt[ta, PT_INV_MASS], pt[ta, PT_INV_INERTIA], rax, ray),
            (bvx, bvy, bw, imb, iib, rbx, rby), ct[c, CT_NX], ct[c, CT_NY],
            (ct[c, CT_DEPTH], mp[MP_STIFFNESS], mp[MP_DAMPING], dt),
            (ct[c, CT_MU_S], ct[c, CT_MU_K], ct[c, CT_V_T]))
        fx[a] += fcx
        fy[a] += fcy
        tz[a] += rax * fcy - ray * fcx
        if b >= 0:
            fx[b] -= fcx
            fy[b] -= fcy
            tz[b] -= rbx * fcy - rby * fcx
        if track:
            acc[A_SPRING] += ps * dt
            acc[A_DAMPER] += pd * dt
            acc[A_CONTACT_FRICTION] += pf * dt
