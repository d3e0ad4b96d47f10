"""Rigid-body dynamics of a serial arm with revolute joints, in CasADi SX (no Pinocchio).

Kinematics follow the standard Denavit-Hartenberg convention (Corke): the
transform from frame ``j-1`` to frame ``j`` is ``Rz(theta_j) Tz(d_j) Tx(a_j)
Rx(alpha_j)``, and frame ``j`` sits at the distal end of link ``j``. Each link's
centre of mass ``r_j`` and inertia ``I_j`` (about the centre of mass) are given
in frame ``j``.

- :func:`rnea` is the recursive Newton-Euler algorithm: joint torques from
  ``q, qd, qdd`` and the base acceleration (gravity enters as an upward base
  acceleration), plus the reflected rotor inertia ``G_j^2 J_m,j qdd_j``.
- :func:`mass_matrix` builds ``M(q)`` column by column as ``rnea(q, 0, e_j)``
  with gravity off; :func:`bias_torque` is ``h(q, qd) = rnea(q, qd, 0)``.
- :func:`forward_dynamics` solves ``M qdd = tau - h`` symbolically (never an
  explicit inverse).

Link data may be SX expressions (tunable parameters) or plain numbers (baked in).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import casadi as ca

__all__ = ["Link", "dh_rotation", "rnea", "mass_matrix", "bias_torque", "forward_dynamics", "kinetic_energy"]


@dataclass(frozen=True)
class Link:
    """One link: DH geometry, mass properties (frame j, SI units) and reflected rotor inertia.

    ``com`` is a 3-vector (m), ``inertia`` a 3x3 matrix (kg m^2) about the centre of mass,
    ``rotor`` is ``G^2 J_m`` (kg m^2, link side). Entries may be SX expressions.
    """

    d: float
    a: float
    alpha: float
    mass: object
    com: object
    inertia: object
    rotor: object = 0.0


def dh_rotation(theta, alpha) -> ca.SX:
    """Rotation part of the DH transform ``Rz(theta) Rx(alpha)`` (frame j axes in frame j-1)."""
    ct, st, ca_, sa = ca.cos(theta), ca.sin(theta), ca.cos(alpha), ca.sin(alpha)
    return ca.vertcat(ca.horzcat(ct, -st * ca_, st * sa),
                      ca.horzcat(st, ct * ca_, -ct * sa),
                      ca.horzcat(0, sa, ca_))


def _forward(links, q, qd, qdd, base_acc):
    """Velocities and accelerations of every link frame, expressed in that frame."""
    z0 = ca.DM([0, 0, 1])
    w, wd, vd = ca.SX.zeros(3), ca.SX.zeros(3), ca.SX(base_acc)
    rots, kin = [], []
    for j, link in enumerate(links):
        R = dh_rotation(q[j], link.alpha)
        Rt = R.T
        pstar = ca.vertcat(link.a, link.d * ca.sin(link.alpha), link.d * ca.cos(link.alpha))
        w_new = Rt @ (w + z0 * qd[j])
        wd = Rt @ (wd + z0 * qdd[j] + ca.cross(w, z0 * qd[j]))
        w = w_new
        vd = ca.cross(wd, pstar) + ca.cross(w, ca.cross(w, pstar)) + Rt @ vd
        rots.append(R)
        kin.append((w, wd, vd, pstar))
    return rots, kin


def rnea(links: Sequence[Link], q, qd, qdd, base_acc) -> ca.SX:
    """Inverse dynamics: joint torques (n, 1) for DH angles ``q``, rates ``qd``, accelerations ``qdd``.

    Parameters
    ----------
    links : sequence of Link
        The ``n`` links from base to tool.
    q, qd, qdd : (n, 1)
        DH joint angles (rad), velocities (rad/s), accelerations (rad/s^2).
    base_acc : (3,)
        Linear acceleration of the base frame in base coordinates (m/s^2);
        ``+g`` upward models gravity, zeros switch it off.

    Returns
    -------
    SX (n, 1): torques in N m, including the rotor term ``G^2 J_m qdd``.
    """
    n = len(links)
    rots, kin = _forward(links, q, qd, qdd, base_acc)
    z0 = ca.DM([0, 0, 1])
    f, nm = ca.SX.zeros(3), ca.SX.zeros(3)
    tau = [None] * n
    for j in reversed(range(n)):
        link, (w, wd, vd, pstar) = links[j], kin[j]
        I = ca.SX(link.inertia)
        r = ca.SX(link.com)
        acc_com = ca.cross(wd, r) + ca.cross(w, ca.cross(w, r)) + vd
        F = link.mass * acc_com
        N = I @ wd + ca.cross(w, I @ w)
        R_next = rots[j + 1] if j + 1 < n else ca.SX.eye(3)
        nm = R_next @ (nm + ca.cross(R_next.T @ pstar, f)) + ca.cross(pstar + r, F) + N
        f = R_next @ f + F
        tau[j] = ca.dot(nm, rots[j].T @ z0) + link.rotor * qdd[j]
    return ca.vertcat(*tau)


def mass_matrix(links: Sequence[Link], q) -> ca.SX:
    """Joint-space inertia ``M(q)`` (n, n), column j = ``rnea(q, 0, e_j)`` without gravity."""
    n = len(links)
    zero = ca.SX.zeros(n)
    cols = [rnea(links, q, zero, ca.SX(ca.DM.eye(n)[:, j]), ca.DM.zeros(3)) for j in range(n)]
    return ca.horzcat(*cols)


def bias_torque(links: Sequence[Link], q, qd, base_acc) -> ca.SX:
    """``h(q, qd)`` (n, 1): Coriolis, centrifugal and gravity torques, ``rnea(q, qd, 0)``."""
    return rnea(links, q, qd, ca.SX.zeros(len(links)), base_acc)


def forward_dynamics(links: Sequence[Link], q, qd, tau, base_acc) -> ca.SX:
    """Joint accelerations (n, 1) solving ``M(q) qdd = tau - h(q, qd)`` symbolically."""
    return ca.solve(mass_matrix(links, q), tau - bias_torque(links, q, qd, base_acc))


def kinetic_energy(links: Sequence[Link], q, qd) -> ca.SX:
    """``0.5 qd^T M(q) qd`` in J (links and rotors)."""
    return 0.5 * ca.dot(qd, mass_matrix(links, q) @ qd)
