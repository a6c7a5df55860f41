"""Adaptive UKF with model error (paper 001, Sect. 4, eq. 92–110).

A UKF whose process and measurement noises have unknown, slowly varying means
``q``, ``p`` and covariances ``Q``, ``R`` ("virtual noises" that absorb model
error, eq. 16–19), estimated on line by a suboptimal MAP estimator with
exponential fading memory. With forgetting factor ``b`` (0 < b < 1) and the
j-th update,

    d_j = (1 − b) / (1 − b^j)                                             (eq. 83, 87)

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

Since Σ wᵐ = 1, eq. 105–106 are q̂ ← q̂ + d·Kε and p̂ ← p̂ + d·ε, and (with the
redrawn points below) eq. 107 and 110 are R̂ ← R̂ + d(εεᵀ − P_zz) and
Q̂ ← Q̂ + d·K(εεᵀ − P_zz)Kᵀ: the Sage–Husa recursions, stationary when the
innovations have the covariance the filter predicts.

Choices (the paper is silent or ambiguous):

* **Points for the update.** The paper pushes the predicted points χ_i(k|k−1)
  through h (eq. 97), whose spread Θ lacks Q̂, so its P_xz and Γ omit Q̂'s
  share. Our UKF (filters/sigma.py) redraws the points from
  (x̂(k|k−1), P(k|k−1)); the AUKF does the same, so Γ and P_xz include Q̂, the
  R̂ update of eq. 107 is unbiased (E[εεᵀ] = Γ + R), and the estimator
  switched off is *exactly* our UKF (``adapt=False``; tested to 1e-12).
  Θ of eq. 95/110 is the spread of the propagated points, without Q̂.
* **Switches.** ``adapt=False`` freezes q̂ = 0, p̂ = 0 and uses the model's
  Q_k, R_k at every step: the plain UKF. The limit b → 0 (d → 1, memory of
  one step) is *not* a UKF: it is the single-sample estimator. ``adapt_q`` /
  ``adapt_r`` switch the covariance estimators; ``adapt_means`` the mean
  estimators: "both" (the paper), "none", "q" or "p" (one).
  q̂ and p̂ are driven by the same innovation, and wherever a measured state
  is a random walk (here velocity, acceleration, heading, depth) a state
  offset c with p̂ offset −c leaves every innovation unchanged: the pair is
  not observable and drifts (tests/test_aukf.py shows it on a linear model).
* **Initial values.** q̂₀ = 0, p̂₀ = 0, Q̂₀ = model Q_0, R̂₀ = model R_0. The
  paper's d₁ = 1 (eq. 83 with k = 1) gives the first innovation full weight:
  its one-sample R̂₁, Q̂₁ are indefinite and the guard decides what replaces
  them (with ``guard="previous"`` or ``"biased"``: the prior Q̂₀, R̂₀).
* **Guard** (the paper has none; the digest allows clipping or keeping the
  previous value). The updated matrix is symmetrised; when it is not positive
  definite at the ``guard_floor`` level (a Cholesky attempt on the matrix in
  the units of the prior, scaled by the square roots of the prior's diagonal,
  minus ``guard_floor``·I), ``guard`` decides:

  - ``"biased"`` (default): use instead the paper's own *biased* estimators,
    eq. 73 for R (R̂ ← (1−d)R̂ + d εεᵀ) and eq. 70 for Q
    (Q̂ ← (1−d)Q̂ + d KεεᵀKᵀ), positive definite for d < 1; at d = 1 (one
    sample) the previous value is kept. Biased upwards (conservative) at the
    steps where it is used.
  - ``"previous"``: keep the previous estimate.
  - ``"clip"``: clip the scaled eigenvalues at ``guard_floor`` (an
    eigendecomposition). After an indefinite one-sample update this leaves
    R̂ near ``guard_floor``·R₀ in most directions: an overconfident filter.

  Every firing is counted (``guard_q``, ``guard_r`` in ``Estimates.info``).
* **Missing components.** When only part of z is present, p̂ and R̂ are updated
  on that block only.
* **Angles.** q̂ and p̂ components of angles are wrapped; residuals are wrapped.
"""

from __future__ import annotations

import numpy as np

from replay.filters.case import Case
from replay.util.angles import residual, weighted_mean, wrap_components
from replay.util.linalg import cholesky

from replay.util.params import Param
from replay.model import remap_indices
from replay.util.linalg import require_spd

from ..kalman import gain_nis
from ..sigma import UKF

GUARDS = ("biased", "previous", "clip")
MEANS = {"both": (True, True), "q": (True, False), "p": (False, True), "none": (False, False)}


class AUKF(UKF):
    """UKF with on-line fading-memory estimates of q, p, Q, R (001 eq. 92–110)."""

    name = "aukf"
    CASE = Case("sim/sauv-current", "dead-reckoning", {"forgetting": 0.95}, first=80)
    PARAMS = UKF.PARAMS + (
        Param(
            "forgetting",
            float,
            0.98,
            "forgetting factor b of the fading memory (eq. 83)",
            low=0.0,
            high=1.0,
            low_open=True,
            high_open=True,
        ),
        Param("adapt", bool, True, "estimate the noise statistics (false: the plain UKF)"),
        Param("adapt_q", bool, True, "estimate the process noise covariance Q (eq. 110)"),
        Param("adapt_r", bool, True, "estimate the measurement noise covariance R (eq. 107)"),
        Param(
            "adapt_means",
            str,
            "both",
            "which noise means to estimate: q (eq. 105), p (eq. 106), both (the paper) or none",
            choices=tuple(MEANS),
        ),
        Param("guard", str, "biased", "what replaces an updated Q or R that is not positive definite", choices=GUARDS),
        Param(
            "guard_floor",
            float,
            1e-3,
            "eigenvalue floor of the guard, in units of the prior",
            low=0.0,
            high=1.0,
            low_open=True,
            high_open=True,
        ),
        Param("keep_history", bool, False, "keep every step's q, p, Q, R in info['history']"),
    )

    def check(self):
        super().check()
        self._qmean, self._pmean = MEANS[self.adapt_means]

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
        state.sq2, state.sr2 = np.outer(state.sq, state.sq), np.outer(state.sr, state.sr)
        state.j = 0
        state.guard_q = state.guard_r = 0
        state.history = {"q": [], "p": [], "Q": [], "R": []} if self.keep_history else None

    def predict(self, state, k):
        if not self.adapt:
            return super().predict(state, k)
        m = state.model
        G = m.f(self._sigma(state, state.x, state.P), k)  # gamma_i (92)
        gm = weighted_mean(G, state.wm, m.x_angles)  # sum wm gamma_i
        # chi_i = gamma_i + q-hat (93) shifts every point alike: its mean is gm + q-hat (94)
        # and its spread about that mean is the spread of gamma_i about gm (95)
        D = residual(G, gm, m.x_angles)
        state.theta = (D.T * state.wc) @ D  # (95)
        state.x = wrap_components(gm + state.q, m.x_angles)  # (94)
        state.P = state.theta + state.Qh  # (96)

    def update(self, state, z, k, mask):
        if not self.adapt:
            return super().update(state, z, k, mask)
        m = state.model
        full = mask is None
        angles = m.z_angles if full else remap_indices(m.z_angles, mask)
        idx = slice(None) if full else np.flatnonzero(mask)
        blk = (slice(None), slice(None)) if full else np.ix_(idx, idx)
        y, Gamma, Pxz, _ = self.innovation(state, z, k, mask)  # y = z - sum wm zeta_i
        R = state.Rh[blk]
        eps = residual(y, state.p[idx], angles)  # (103): z - (sum wm zeta_i + p-hat)
        S = Gamma + R  # (101)
        K, state.nis = gain_nis(S, Pxz, eps)  # (108); NIS of the corrected innovation eps
        Ke = K @ eps
        x = wrap_components(state.x + Ke, m.x_angles)  # (104)
        P = state.P - K @ S @ K.T  # (109)
        state.x, state.P = x, 0.5 * (P + P.T)
        state.j += 1
        b = self.forgetting
        d = (1.0 - b) / (1.0 - b**state.j)
        # (105)-(106) as increments: x(k|k) - sum wm gamma_i = q-hat + K eps (94, 104) and
        # z - sum wm zeta_i = p-hat + eps (103), so (1 - d) q-hat + d [...] = q-hat + d K eps
        if self._qmean:
            state.q = wrap_components(state.q + d * Ke, m.x_angles)  # (105)
        if self._pmean:
            state.p[idx] += d * eps  # (106)
            wrap_components(state.p, m.z_angles)
        ee = np.outer(eps, eps)
        if self.adapt_r:
            Rn = state.Rh.copy()
            Rn[blk] = (1 - d) * R + d * (ee - Gamma)  # (107)
            Rn, fired = self._guard(Rn, state.sr, state.sr2, state.Rh, blk, ee, d)
            state.Rh = Rn
            state.guard_r += fired
        if self.adapt_q:
            KeKe = np.outer(Ke, Ke)
            Qn = (1 - d) * state.Qh + d * (KeKe + state.P - state.theta)  # (110)
            Qn, fired = self._guard(Qn, state.sq, state.sq2, state.Qh, None, KeKe, d)
            state.Qh = Qn
            state.guard_q += fired
        if state.history is not None:
            h = state.history
            h["q"].append(state.q.copy()), h["p"].append(state.p.copy())
            h["Q"].append(state.Qh.copy()), h["R"].append(state.Rh.copy())

    def _guard(self, M, scale, scale2, previous, blk, sample, d):
        """(M or its replacement, 1 if the guard fired else 0); see the module docstring.

        ``sample`` is εεᵀ (for R, eq. 73) or KεεᵀKᵀ (for Q, eq. 70): the biased
        replacement is (1 − d)·previous + d·sample on the block ``blk``.
        """
        M = 0.5 * (M + M.T)
        if is_spd(M, scale2, self.guard_floor):
            return M, 0
        if self.guard == "clip":
            return clip_spd(M, scale, self.guard_floor), 1
        if self.guard == "biased" and d < 1.0:
            if blk is None:
                out = (1 - d) * previous + d * sample
            else:
                out = previous.copy()
                out[blk] = (1 - d) * previous[blk] + d * sample
            out = 0.5 * (out + out.T)
            if is_spd(out, scale2, self.guard_floor):
                return out, 1
        return previous, 1

    def finish(self, state, info):
        info["adapt"] = self.adapt
        if not self.adapt:
            return
        info.update(
            guard_q=int(state.guard_q),
            guard_r=int(state.guard_r),
            adapt_updates=int(state.j),
            Q_hat=state.Qh,
            R_hat=state.Rh,
            q_hat=state.q,
            p_hat=state.p,
        )
        if state.history is not None:
            info["history"] = {k: np.array(v) for k, v in state.history.items()}


def is_spd(M: np.ndarray, scale2: np.ndarray, floor: float) -> bool:
    """True when diag(s) M diag(s) − floor·I has a Cholesky factor (M symmetric, scale2 = s sᵀ)."""
    Ms = M * scale2
    Ms.flat[:: len(Ms) + 1] -= floor
    try:
        cholesky(Ms)
    except np.linalg.LinAlgError:
        return False
    return True


def clip_spd(M: np.ndarray, scale: np.ndarray, floor: float) -> np.ndarray:
    """Symmetric M with the eigenvalues of diag(scale) M diag(scale) clipped at ``floor``."""
    Ms = M * scale[:, None] * scale[None, :]
    w, V = np.linalg.eigh(Ms)
    if not np.all(np.isfinite(w)):
        raise np.linalg.LinAlgError("noise estimate is not finite")
    Ms = (V * np.maximum(w, floor)) @ V.T
    inv = 1.0 / scale
    return 0.5 * (Ms + Ms.T) * inv[:, None] * inv[None, :]


def guard_spd(M: np.ndarray, scale: np.ndarray, floor: float):
    """(M', fired): M symmetrised, eigenvalues of diag(scale) M diag(scale) clipped at ``floor``.

    ``scale`` is 1/sqrt(diag) of the prior matrix, so the floor is relative and
    unit-free. ``fired`` is 1 when clipping was needed, else 0 (then M' is M
    symmetrised, untouched otherwise).
    """
    M = 0.5 * (M + M.T)
    if is_spd(M, np.outer(scale, scale), floor):
        return M, 0
    return clip_spd(M, scale, floor), 1


def final_estimate(estimates: list, key: str, component: int | None = None, magnitude: bool = False) -> float:
    """Mean over runs (each run's :class:`Estimates`) of the AUKF's final ``info[key]``: of ``q_hat``, ``p_hat``,
    the diagonal of ``Q_hat``, ``R_hat``, or the firings ``guard_q``, ``guard_r``; of its ``component`` (None:
    the mean over the components), of the absolute values if ``magnitude``."""
    values = [np.atleast_1d(np.asarray(e.info[key], float)) for e in estimates]
    values = [np.diagonal(v) if v.ndim == 2 else v for v in values]
    values = [np.abs(v) if magnitude else v for v in values]
    return float(np.mean([v.mean() if component is None else v[component] for v in values]))


def history(estimates: list, key: str, column: int) -> np.ndarray:
    """(runs, updates) array of component ``column`` of the estimate ``key`` (``"q"``, ``"p"``; of ``"Q"``,
    ``"R"``: a row) at every update, from each run's :class:`Estimates` ``info["history"]`` (``keep_history=True``)."""
    return np.stack([np.asarray(e.info["history"][key], float)[:, column] for e in estimates])
