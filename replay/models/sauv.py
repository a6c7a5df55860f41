"""Small-AUV dead-reckoning model of paper 001 (eq. 1–13), discretised.

State (10), in the paper's north-east-down navigation frame n and body frame b
(x forward, y starboard, z down):

    x = [p_N, p_E, p_D, v_xb, v_yb, v_zb, a_xb, a_yb, a_zb, psi]   (:data:`COMPONENTS`)

(``p_D`` is depth, positive down; ``psi`` the heading, 0 = north, clockwise
positive, radians). Roll gamma and pitch theta are *not* states (001 note 1):
they come from the AHRS and enter as known per-step inputs ``roll[k]``,
``pitch[k]`` (NED convention: pitch positive nose up, roll positive starboard
down).

Continuous model (eq. 2, 4–13) and our discretisation with step T:

    p' = R(psi) C_b^h(theta, gamma) v_b            (4–6; C_b^h of eq. 1)
    v_b' = a_b                                       (7–9)
    a_b' = -alpha_b (a_b - a_bar),  psi' = -alpha_psi (psi - psi_bar)   (10–13 with G Lambda_bar)

    p_k = p_{k-1} + T R(psi) C_b^h (v + a T/2),  v_k = v_{k-1} + a T,
    a_k = a_bar + e^{-alpha_b T} (a_{k-1} - a_bar),  psi_k likewise.

Choices, written down where they are made:

* **Heading sign.** Eq. 4–5 print R(psi)ᵀ (p_y' = -sin psi C11 v_x + ...), an
  anticlockwise heading. We use the usual NED heading (clockwise from north,
  p_E' = +sin psi ...) so an AHRS heading enters unchanged.
* **Mean manoeuvre Lambda_bar.** The paper's input B X̄_SUB(k−1) is taken from
  the previous estimate (algorithm step 5). Applied to each sigma point
  (``mean_maneuver="previous"``, default) that makes a_bar = a and
  psi_bar = psi: acceleration and heading are random walks driven by Q, and
  alpha_b, alpha_psi drop out. ``mean_maneuver="zero"`` is the Singer reading
  (decay towards zero with alpha_xb = alpha_yb = alpha_zb = 1,
  alpha_psi = 0.1 as in 001 §5).
* **Measurements** (eq. 3): y = [p_D, v_b, a_b, psi] = x[2:], H = [0_{8x2} I_8].
  ``measured`` selects other components (e.g. GPS north/east at the surface);
  ``z_angles`` follows.
* **Noise.** The paper gives no Q, R: :func:`default_R` builds R from the
  sensor error budget of 001 §5 and :data:`Q_DEFAULT` is our nominal
  process noise per step (the AUKF estimates both).
"""

from __future__ import annotations

import numpy as np

from replay.util.angles import wrap
from replay.model import Model

KNOT = 1852.0 / 3600.0
DEG = np.pi / 180.0
PAPER_MEASURED = (2, 3, 4, 5, 6, 7, 8, 9)
COMPONENTS = ("north", "east", "depth", "vx", "vy", "vz", "ax", "ay", "az", "heading")

# nominal process noise per step of 0.5 s (ours; the paper gives none)
Q_DEFAULT = np.diag([0.01**2, 0.01**2, 0.01**2, 0.01**2, 0.01**2, 0.01**2, 0.02**2, 0.02**2, 0.02**2, (0.2 * DEG) ** 2])


def default_R(dt: float = 0.5, depth_full_scale: float = 50.0, speed: float = 4 * KNOT):
    """R from 001 §5: depth 3 % of full scale, DVL 1 % (of ``speed``), accelerometer
    0.02 m/(s^2 sqrt(Hz)) white at rate 1/dt, AHRS heading 2 deg (1 sigma)."""
    acc = 0.02 * np.sqrt(1.0 / dt)
    return np.diag([(0.03 * depth_full_scale) ** 2] + [(0.01 * speed) ** 2] * 3 + [acc**2] * 3 + [(2.0 * DEG) ** 2])


def body_to_level(pitch, roll):
    """C_b^h of eq. 1 for arrays of pitch theta and roll gamma: (..., 3, 3)."""
    ct, st, cg, sg = np.cos(pitch), np.sin(pitch), np.cos(roll), np.sin(roll)
    z = np.zeros_like(ct)
    return np.stack(
        [np.stack([ct, st * sg, st * cg], -1), np.stack([z, cg, -sg], -1), np.stack([-st, ct * sg, ct * cg], -1)], -2
    )


class SAUV(Model):
    """Paper 001's 10-state model with AHRS roll/pitch as inputs (see module docstring)."""

    nx = 10
    x_angles = (9,)
    components = COMPONENTS

    def __init__(
        self,
        dt=0.5,
        pitch=0.0,
        roll=0.0,
        Q=None,
        R=None,
        measured=PAPER_MEASURED,
        mean_maneuver: str = "previous",
        alpha_b: float = 1.0,
        alpha_psi: float = 0.1,
    ):
        self.dt = np.asarray(dt, float)
        self.pitch = np.asarray(pitch, float)
        self.roll = np.asarray(roll, float)
        self.measured = tuple(int(i) for i in measured)
        self.nz = len(self.measured)
        self.z_angles = tuple(j for j, i in enumerate(self.measured) if i == 9)
        self.Q = Q_DEFAULT.copy() if Q is None else np.asarray(Q, float)
        if R is None:
            R = (
                default_R(float(np.median(self.dt)))[
                    np.ix_([i - 2 for i in self.measured], [i - 2 for i in self.measured])
                ]
                if all(i >= 2 for i in self.measured)
                else np.eye(self.nz)
            )
        self.R = np.asarray(R, float)
        if mean_maneuver not in ("previous", "zero"):
            raise ValueError("mean_maneuver must be 'previous' or 'zero'")
        self.mean_maneuver = mean_maneuver
        self.alpha_b, self.alpha_psi = float(alpha_b), float(alpha_psi)
        self._C = body_to_level(self.pitch, self.roll)

    def _at(self, a, k):
        return a if a.ndim == 0 else a[k]

    def f(self, x, k):
        T = float(self._at(self.dt, k))
        C = self._C if self._C.ndim == 2 else self._C[k]
        v = x[..., 3:6] + 0.5 * T * x[..., 6:9]
        vh = v @ C.T  # level-frame velocity (eq. 4-6)
        c, s = np.cos(x[..., 9]), np.sin(x[..., 9])
        y = x.copy()
        y[..., 0] += T * (c * vh[..., 0] - s * vh[..., 1])
        y[..., 1] += T * (s * vh[..., 0] + c * vh[..., 1])
        y[..., 2] += T * vh[..., 2]
        y[..., 3:6] += T * x[..., 6:9]
        if self.mean_maneuver == "zero":
            y[..., 6:9] *= np.exp(-self.alpha_b * T)
            y[..., 9] = wrap(y[..., 9] * np.exp(-self.alpha_psi * T))
        return y

    def h(self, x, k):
        return x[..., self.measured]
