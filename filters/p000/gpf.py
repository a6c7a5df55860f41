"""Grey particle filter (GPF) of paper 000, §2.4 (Li, Zhao, Huang, Su).

A bootstrap particle filter with two changes. Each step k:

1. **Sampling** (eq. 20-22). N_std = N - N_grey particles propagate through the
   motion model (eq. 20, ``model.sample_f``, from ancestors resampled by the
   previous weights); N_grey particles are drawn around the GM(1,1) grey
   prediction of each measured channel from its last L measurements
   z_{k-L..k-1} (eq. 21, :func:`replay.filters.p000.grey.gm11_predict`):
   x^j_k = x^grey_k + u^j_k, u ~ N(0, Q_k) (eq. 22).
2. **Weighting** (eq. 13-19, 23). R_k = diag(sigma_1^2, ...) with each sigma
   re-estimated from the last ``noise_window`` measurements (z_k included) by
   the db6 wavelet estimator (eq. 17, :class:`replay.filters.p000.wavelet_noise.WaveletNoise`);
   w^j ∝ exp(-1/2 (z_k - x^j)' R_k^-1 (z_k - x^j)) (eq. 23, wrapped angle residuals).
3. Estimate = weighted mean (eq. 24; circular for angles); resample (step 5)
   every step, systematic.

Paper parameters (§3): N = 1000, N_grey = 100 (N_grey : N_std = 1 : 9), grey
window L = 30, noise window 50, polynomial order M = 5, db6.

Choices made here (the paper does not say):

* The grey prediction is of the *measurements*, so the model must measure its
  state directly (eq. 6, ``h(x) = x``); checked when a run starts.
* Before L finite measurements of every channel exist, or while one of the
  last L is missing, all N particles are standard (no grey particles); the
  steps with grey particles are counted in ``info["grey_steps"]``.
* Before ``noise_window`` measurements exist, and for a channel with a
  missing value in its window, the weighting uses the last wavelet estimate of
  that channel, or the model's R before the first one. ``sigma_floor`` keeps
  R positive on a quantised, constant sensor.
* The weights are the likelihood alone (eq. 23), as printed: the mixture
  proposal (model + grey) is not corrected for in the weights.
* Ablations: ``grey=False`` (no grey particles: a bootstrap PF with wavelet R),
  ``wavelet=False`` (the model's fixed R, as EKF and MMPF) and ``grey_response``
  (the GM(1,1) time response: the fitted discrete equation's, the default; eq. 12
  derived from eq. 11; eq. 12 with its printed factor, see
  :mod:`replay.filters.p000.grey`). ``replay reproduce 000`` runs them.
"""

from __future__ import annotations

import numpy as np

from replay.filters.case import Case
from replay.util.angles import residual, wrap_components
from replay.util.errors import ReplayError
from replay.util.linalg import cholesky
from replay.util.params import Param
from replay.model import remap_indices

from .. import particles
from ..base import Filter
from ..resampling import SCHEMES
from .grey import RESPONSES, GreyPredictor
from .wavelet_noise import WaveletNoise


class GreyParticleFilter(Filter):
    """GPF: grey-model particles plus wavelet-estimated measurement noise (paper 000)."""

    name = "gpf"
    CASE = Case("sim/lake-depth", "depth", {"n_particles": 200, "n_grey": 20}, first=60)
    PARAMS = (
        Param("n_particles", int, 1000, "particles N (000 §3: 1000)", low=2),
        Param("n_grey", int, 100, "grey particles N_grey among the N (000 §3: 100, N_grey : N_std = 1 : 9)", low=0),
        Param("grey_window", int, 30, "GM(1,1) window L (eq. 7; 000 §3: 30)", unit="steps", low=3),
        Param("noise_window", int, 50, "wavelet noise window (eq. 17; 000 §3: 50)", unit="steps", low=1),
        Param("wavelet_name", str, "db6", "wavelet of the noise estimator (000 §3: db6)"),
        Param("grey", bool, True, "draw grey particles (false: a bootstrap PF with the wavelet R)"),
        Param("wavelet", bool, True, "estimate R by wavelets (false: the model's fixed R)"),
        Param("grey_alpha", float, 0.5, "GM(1,1) background weight alpha (eq. 10)", low=0.0, high=1.0),
        Param(
            "grey_response",
            str,
            "discrete",
            "GM(1,1) time response: of the fitted discrete equation; "
            "eq. 12 derived from eq. 11, (1 - e^a); or eq. 12 with the printed factor (1 - e^-a), about the "
            "negated prediction (filters/p000/grey.py)",
            choices=RESPONSES,
        ),
        Param(
            "grey_floor",
            float,
            1.0,
            "GM(1,1) conditioning shift applies when the window dips below this (null: never)",
            optional=True,
        ),
        Param("grey_shift_ratio", float, 100.0, "GM(1,1) conditioning shift: max(floor, ratio * span) - min", low=0.0),
        Param("sigma_floor", float, 1e-6, "lower bound of each wavelet sigma", low=0.0, low_open=True),
        Param("resampling", str, "systematic", "resampling scheme (every step)", choices=tuple(SCHEMES)),
    )

    def check(self):
        """n_grey < n_particles; the wavelet accepts the window. Builds the two estimators."""
        if self.n_grey >= self.n_particles:
            raise ReplayError(f"{self.owner()}: n_grey must be < n_particles = {self.n_particles} (got {self.n_grey})")
        try:
            self._noise = WaveletNoise(self.noise_window, self.wavelet_name)
        except ReplayError as err:
            raise ReplayError(f"{self.owner()}: noise_window / wavelet_name: {err}") from None
        self._grey = GreyPredictor(
            self.grey_window, self.grey_alpha, self.grey_response, self.grey_floor, self.grey_shift_ratio
        )

    # ------------------------------------------------------------------ run
    def start(self, state, x0, P0):
        super().start(state, x0, P0)
        m = state.model
        probe = np.asarray(x0, float) + np.arange(1.0, m.nx + 1.0)
        if m.nz != m.nx or not np.allclose(m.h(probe[None], 0)[0], probe):
            raise ReplayError(
                f"{self.owner()}: the model must measure its state directly (h(x) = x, eq. 6); "
                f"this one has nx={m.nx}, nz={m.nz}"
            )
        N = self.n_particles
        X = particles.gaussian(state.x[None], state.P[None], N, [state.rng])[0]
        state.particles = wrap_components(X, m.x_angles)
        state.w = np.full(N, 1.0 / N)
        state.hist = np.full((max(self.grey_window, self.noise_window), m.nz), np.nan)
        state.sigma = np.sqrt(np.diagonal(m.measurement_cov(0))).copy()
        state.first = True
        state.grey_steps = state.wavelet_steps = 0
        state.ess_sum, state.steps = 0.0, 0

    def predict(self, state, k):
        m, rng, N = state.model, state.rng, self.n_particles
        g = self._grey_prediction(state) if self.grey and self.n_grey else None
        n_std = N if g is None else N - self.n_grey
        if state.first:
            idx = np.arange(N) if n_std == N else rng.choice(N, n_std, replace=False)
            state.first = False
        else:  # step 5 of the previous step: n_std ancestors from its weights
            idx = SCHEMES[self.resampling](state.w, rng, n_std)
        X = m.sample_f(state.particles[idx], k, rng)  # eq. 20
        if g is not None:  # eq. 22
            u = rng.standard_normal((self.n_grey, m.nx)) @ cholesky(m.process_cov(k)).T
            X = np.concatenate([X, g + u])
            state.grey_steps += 1
        state.particles = wrap_components(X, m.x_angles)
        state.w = np.full(N, 1.0 / N)
        state.hist[:-1] = state.hist[1:]
        state.hist[-1] = np.nan  # z_k, filled by update when measured

    def _grey_prediction(self, state):
        """Eq. 21: GM(1,1) of each channel over z_{k-L..k-1}; None if one is missing."""
        win = state.hist[-self.grey_window :]
        if not np.isfinite(win).all():
            return None
        return wrap_components(self._grey(win), state.model.z_angles)

    def update(self, state, z, k, mask):
        m = state.model
        state.hist[-1] = z
        if self.wavelet:
            win = state.hist[-self.noise_window :]
            full = np.isfinite(win).all(axis=0)
            if full.any():
                s = self._noise.sigma(win[:, full])
                state.sigma[full] = np.maximum(s, self.sigma_floor)
                state.wavelet_steps += 1
        else:
            state.sigma = np.sqrt(np.diagonal(m.measurement_cov(k)))
        angles = m.z_angles
        sig = state.sigma
        if mask is not None:
            z, sig, angles = z[mask], sig[mask], remap_indices(m.z_angles, mask)
            d = residual(z, state.particles[:, mask], angles)
        else:
            d = residual(z, state.particles, angles)
        logw = -0.5 * ((d * d) @ (1.0 / (sig * sig)))  # eq. 23
        state.w = particles.normalise(logw[None])[0][0]

    def estimate(self, state):
        w = state.w[None]
        x, P = particles.estimate(state.particles[None], w, state.model.x_angles)  # eq. 24
        state.ess_sum += float(particles.ess(w)[0])
        state.steps += 1
        return x[0], P[0]

    def finish(self, state, info):
        info.update(
            grey_steps=state.grey_steps,
            wavelet_steps=state.wavelet_steps,
            mean_ess=state.ess_sum / max(state.steps, 1),
            last_sigma=state.sigma.tolist(),
        )
