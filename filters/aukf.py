"""Adaptive UKF with model error (paper 001, Sect. 4, eq. 92–110).

A UKF whose process and measurement noises have unknown, slowly varying means
``q``, ``p`` and covariances ``Q``, ``R`` ("virtual noises" that absorb model
error, eq. 16–19), estimated on line by a suboptimal MAP estimator with
exponential fading memory. With forgetting factor ``b`` (0 < b < 1) and the
j-th update,

    d_j = (1 − b) / (1 − b^j)                                             (eq. 85–87)

Predict (γ_i = f(χ_i(k−1|k−1)), the paper's B·X̄_SUB input is part of the model's f):

    χ_i(k|k−1) = γ_i + q̂(k−1)                                                  (92–93)
    x̂(k|k−1) = Σ wᵐ χ_i,  Θ = Σ wᶜ (χ_i − x̂)(χ_i − x̂)ᵀ,  P(k|k−1) = Θ + Q̂(k−1)     (94–96)

Update (ζ_i = h(χ_i), Z_i = ζ_i + p̂(k−1)):

    ẑ = Σ wᵐ Z_i,  Γ = Σ wᶜ (Z_i − ẑ)(Z_i − ẑ)ᵀ,  P_zz = Γ + R̂(k−1),  P_xz   (97–102)
    ε = z − ẑ,  K = P_xz P_zz⁻¹,  x̂ = x̂(k|k−1) + K ε,  P = P(k|k−1) − K P_zz Kᵀ   (103–104, 108–109)
    q̂ = (1 − d) q̂ + d [x̂(k|k) − Σ wᵐ γ_i]                                       (105)
    p̂ = (1 − d) p̂ + d [z − Σ wᵐ ζ_i]                                            (106)
    R̂ = (1 − d) R̂ + d [ε εᵀ − Γ]                                                (107)
    Q̂ = (1 − d) Q̂ + d [K ε εᵀ Kᵀ + P(k|k) − Θ]                                  (110)

Choices (the paper is silent or ambiguous):

* **Points for the update.** The paper pushes the predicted points χ_i(k|k−1)
  through h (eq. 97). Our UKF (filters/sigma.py) redraws the points from
  (x̂(k|k−1), P(k|k−1)) so that the spread includes Q̂; the AUKF does the same,
  so Γ and P_xz are those of the redrawn points and the estimator switched off
  is *exactly* our UKF (``adapt=False``; tested to 1e-12).
* **Switch.** ``adapt=False`` freezes q̂ = 0, p̂ = 0 and uses the model's Q_k,
  R_k at every step: the plain UKF. The limit b → 0 (d → 1, memory of one
  step) is *not* a UKF: it is the single-sample estimator, which the guard
  below would clip at almost every step. ``adapt_q`` / ``adapt_r`` switch the
  covariance estimators separately, ``adapt_means`` the mean estimators.
* **Initial values.** q̂₀ = 0, p̂₀ = 0, Q̂₀ = model Q_0, R̂₀ = model R_0 (the
  model's nominal noise is the prior of the estimator). d₁ = 1, so the first
  update replaces Q̂₀, R̂₀ by a one-sample estimate (usually indefinite: the
  guard fires, as it should).
* **Guard.** R̂ and Q̂ of eq. 107 and 110 are differences of matrices and can
  lose positive definiteness. After each update the matrix is symmetrised and,
  in the units of the prior (scaled by the square roots of the prior's
  diagonal, so depth in metres and heading in radians are treated alike), its
  eigenvalues are clipped from below at ``guard_floor``. Every clip is counted
  (``guard_q``, ``guard_r`` in ``Estimates.info``).
* **Missing components.** When only part of z is present, p̂ and R̂ are updated
  on that block only.
* **Angles.** q̂ and p̂ components of angles are wrapped; residuals are wrapped.
"""
from __future__ import annotations

import numpy as np

from replay.angles import residual, weighted_mean, wrap_components
from replay.errors import ReplayError
from replay.linalg import cholesky, gain
from replay.model import remap_indices
from replay.noise import require_spd

from .sigma import UKF


class AUKF(UKF):
    """UKF with on-line fading-memory estimates of q, p, Q, R (001 eq. 92–110)."""

    name = "aukf"

    def __init__(self, alpha: float = 0.5, beta: float = 2.0, kappa: float = 0.0,
                 forgetting: float = 0.98, adapt: bool = True, adapt_q: bool = True,
                 adapt_r: bool = True, adapt_means: bool = True, guard_floor: float = 1e-3,
                 keep_history: bool = False):
        super().__init__(alpha, beta, kappa)
        b = float(forgetting)
        if not 0.0 < b < 1.0:
            raise ReplayError(f"aukf: forgetting factor forgetting={b:g} must lie in (0, 1)")
        if not 0.0 < float(guard_floor) < 1.0:
            raise ReplayError(f"aukf: guard_floor={guard_floor:g} must lie in (0, 1)")
        self.forgetting = b
        self.adapt, self.adapt_q, self.adapt_r = bool(adapt), bool(adapt_q), bool(adapt_r)
        self.adapt_means = bool(adapt_means)
        self.guard_floor = float(guard_floor)
        self.keep_history = bool(keep_history)

    # ------------------------------------------------------------------ run
    def start(self, state, x0, P0):
        super().start(state, x0, P0)
        m = state.model
        if not self.adapt:
            return
        state.Qh = require_spd(m.process_cov(0), "aukf: model Q").copy()
        state.Rh = require_spd(m.measurement_cov(0), "aukf: model R").copy()
        state.q = np.zeros(m.nx)
        state.p = np.zeros(m.nz)
        state.sq = 1.0 / np.sqrt(np.diagonal(state.Qh))
        state.sr = 1.0 / np.sqrt(np.diagonal(state.Rh))
        state.j = 0
        state.guard_q = state.guard_r = 0
        state.history = {"q": [], "p": [], "Q": [], "R": []} if self.keep_history else None

    def predict(self, state, k):
        if not self.adapt:
            return super().predict(state, k)
        m = state.model
        G = m.f(self._sigma(state, state.x, state.P), k)  # gamma_i (92)
        state.gm = weighted_mean(G, state.wm, m.x_angles)  # sum wm gamma_i (105)
        Y = wrap_components(G + state.q, m.x_angles)  # chi_i(k|k-1) (93)
        x = weighted_mean(Y, state.wm, m.x_angles)  # (94)
        D = residual(Y, x, m.x_angles)
        state.theta = (D.T * state.wc) @ D  # (95)
        state.x = x
        state.P = state.theta + state.Qh  # (96)

    def innovation(self, state, z, k, mask):
        if not self.adapt:
            return super().innovation(state, z, k, mask)
        # the base class forms residuals against sum wm zeta_i and uses the model's R;
        # swap in R-hat (its block for the components present)
        y, Gamma, Pxz, _ = super().innovation(state, z, k, mask)
        idx = slice(None) if mask is None else np.flatnonzero(mask)
        R = state.Rh if mask is None else state.Rh[np.ix_(idx, idx)]
        return y, Gamma, Pxz, R

    def update(self, state, z, k, mask):
        if not self.adapt:
            return super().update(state, z, k, mask)
        m = state.model
        angles = m.z_angles if mask is None else remap_indices(m.z_angles, mask)
        idx = slice(None) if mask is None else np.flatnonzero(mask)
        y, Gamma, Pxz, R = self.innovation(state, z, k, mask)  # y = z - sum wm zeta_i
        eps = residual(y, state.p[idx], angles)  # (103): z - (sum wm zeta_i + p-hat)
        S = Gamma + R  # (101)
        K = gain(S, Pxz)  # (108)
        Ke = K @ eps
        x = wrap_components(state.x + Ke, m.x_angles)  # (104)
        P = state.P - K @ S @ K.T  # (109)
        P = 0.5 * (P + P.T)
        state.x, state.P = x, P
        state.j += 1
        b = self.forgetting
        d = (1.0 - b) / (1.0 - b**state.j)
        if self.adapt_means:
            state.q = wrap_components((1 - d) * state.q + d * residual(x, state.gm, m.x_angles),
                                      m.x_angles)  # (105)
            p = state.p.copy()
            p[idx] = (1 - d) * p[idx] + d * y  # (106)
            state.p = wrap_components(p, m.z_angles)
        if self.adapt_r:
            blk = np.ix_(idx, idx) if mask is not None else (slice(None), slice(None))
            Rn = state.Rh.copy()
            Rn[blk] = (1 - d) * R + d * (np.outer(eps, eps) - Gamma)  # (107)
            state.Rh, fired = guard_spd(Rn, state.sr, self.guard_floor)
            state.guard_r += fired
        if self.adapt_q:
            Qn = (1 - d) * state.Qh + d * (np.outer(Ke, Ke) + P - state.theta)  # (110)
            state.Qh, fired = guard_spd(Qn, state.sq, self.guard_floor)
            state.guard_q += fired
        if state.history is not None:
            h = state.history
            h["q"].append(state.q.copy()), h["p"].append(state.p.copy())
            h["Q"].append(state.Qh.copy()), h["R"].append(state.Rh.copy())

    def finish(self, state, info):
        info["adapt"] = self.adapt
        if not self.adapt:
            return
        info.update(guard_q=int(state.guard_q), guard_r=int(state.guard_r), adapt_updates=int(state.j),
                    Q_hat=state.Qh, R_hat=state.Rh, q_hat=state.q, p_hat=state.p)
        if state.history is not None:
            info["history"] = {k: np.array(v) for k, v in state.history.items()}


def guard_spd(M: np.ndarray, scale: np.ndarray, floor: float):
    """(M', fired): M symmetrised, eigenvalues of diag(scale) M diag(scale) clipped at ``floor``.

    ``scale`` is 1/sqrt(diag) of the prior matrix, so the floor is relative and
    unit-free. ``fired`` is 1 when clipping was needed, else 0 (then M' is M
    symmetrised, untouched otherwise).
    """
    M = 0.5 * (M + M.T)
    Ms = M * scale[:, None] * scale[None, :]
    try:
        cholesky(Ms - floor * np.eye(len(M)))
        return M, 0
    except np.linalg.LinAlgError:
        pass
    w, V = np.linalg.eigh(Ms)
    if not np.all(np.isfinite(w)):
        raise np.linalg.LinAlgError("noise estimate is not finite")
    Ms = (V * np.maximum(w, floor)) @ V.T
    inv = 1.0 / scale
    return 0.5 * (Ms + Ms.T) * inv[:, None] * inv[None, :], 1
