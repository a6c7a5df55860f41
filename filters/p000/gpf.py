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
* Ablations: ``grey=False`` (no grey particles: a bootstrap PF with wavelet R)
  and ``wavelet=False`` (the model's fixed R, as EKF and MMPF).
"""
from __future__ import annotations

import numpy as np

from replay.util.angles import residual, weighted_mean, wrap_components
from replay.util.errors import ReplayError
from replay.util.linalg import cholesky
from replay.model import remap_indices

from ..base import Filter
from .grey import GreyPredictor
from ..resampling import SCHEMES, effective_sample_size
from .wavelet_noise import WaveletNoise


class GreyParticleFilter(Filter):
    """GPF: grey-model particles plus wavelet-estimated measurement noise (paper 000)."""

    name = "gpf"

    def __init__(self, n_particles: int = 1000, n_grey: int = 100, grey_window: int = 30,
                 noise_window: int = 50, wavelet_name: str = "db6", grey: bool = True,
                 wavelet: bool = True, grey_alpha: float = 0.5, grey_response: str = "discrete",
                 grey_floor: float = 1.0, grey_shift_ratio: float = 100.0,
                 sigma_floor: float = 1e-6, resampling: str = "systematic"):
        for name, v, lo in (("n_particles", n_particles, 2), ("n_grey", n_grey, 0),
                            ("grey_window", grey_window, 3), ("noise_window", noise_window, 1)):
            if not isinstance(v, (int, np.integer)) or isinstance(v, bool) or v < lo:
                raise ReplayError(f"gpf: {name} must be an integer >= {lo} (got {v!r})")
        if n_grey >= n_particles:
            raise ReplayError(f"gpf: n_grey ({n_grey}) must be smaller than n_particles ({n_particles})")
        if resampling not in SCHEMES:
            raise ReplayError(f"gpf: resampling must be one of {', '.join(SCHEMES)} (got {resampling!r})")
        if grey_response not in ("discrete", "continuous"):
            raise ReplayError(f"gpf: grey_response must be 'discrete' or 'continuous' (got {grey_response!r})")
        if not 0.0 <= grey_alpha <= 1.0:
            raise ReplayError(f"gpf: grey_alpha must be in [0, 1] (got {grey_alpha!r})")
        if not sigma_floor > 0:
            raise ReplayError(f"gpf: sigma_floor must be positive (got {sigma_floor!r})")
        self.n_particles, self.n_grey = int(n_particles), int(n_grey)
        self.grey_window, self.noise_window = int(grey_window), int(noise_window)
        self.wavelet_name, self.grey, self.wavelet = wavelet_name, bool(grey), bool(wavelet)
        self.grey_alpha, self.grey_response = float(grey_alpha), grey_response
        self.grey_floor, self.grey_shift_ratio = grey_floor, float(grey_shift_ratio)
        self.sigma_floor, self.resampling = float(sigma_floor), resampling
        self._noise = WaveletNoise(self.noise_window, wavelet_name)  # validates window and wavelet
        self._grey = GreyPredictor(self.grey_window, self.grey_alpha, grey_response, grey_floor,
                                   self.grey_shift_ratio)

    # ------------------------------------------------------------------ run
    def start(self, state, x0, P0):
        super().start(state, x0, P0)
        m = state.model
        probe = np.asarray(x0, float) + np.arange(1.0, m.nx + 1.0)
        if m.nz != m.nx or not np.allclose(m.h(probe[None], 0)[0], probe):
            raise ReplayError("gpf: the model must measure its state directly (h(x) = x, eq. 6); "
                              f"this one has nx={m.nx}, nz={m.nz}")
        L = np.linalg.cholesky(np.asarray(P0, float))
        N = self.n_particles
        state.particles = state.x + state.rng.standard_normal((N, m.nx)) @ L.T
        wrap_components(state.particles, m.x_angles)
        state.w = np.full(N, 1.0 / N)
        state.hist = np.full((max(self.grey_window, self.noise_window), m.nz), np.nan)
        state.sigma = np.sqrt(np.diagonal(m.measurement_cov(0))).copy()
        state.first = True
        state.grey_steps = state.wavelet_steps = 0
        state.ess_sum, state.steps = 0.0, 0
        state._resample = SCHEMES[self.resampling]

    def predict(self, state, k):
        m, rng, N = state.model, state.rng, self.n_particles
        g = self._grey_prediction(state) if self.grey and self.n_grey else None
        n_std = N if g is None else N - self.n_grey
        if state.first:
            idx = np.arange(N) if n_std == N else rng.choice(N, n_std, replace=False)
            state.first = False
        else:
            idx = state._resample(state.w, rng, n_std)
        particles = m.sample_f(state.particles[idx], k, rng)  # eq. 20
        if g is not None:  # eq. 22
            u = rng.standard_normal((self.n_grey, m.nx)) @ cholesky(m.process_cov(k)).T
            particles = np.concatenate([particles, g + u])
            state.grey_steps += 1
        state.particles = wrap_components(particles, m.x_angles)
        state.w = np.full(N, 1.0 / N)
        state.hist[:-1] = state.hist[1:]
        state.hist[-1] = np.nan  # z_k, filled by update when measured

    def _grey_prediction(self, state):
        """Eq. 21: GM(1,1) of each channel over z_{k-L..k-1}; None if one is missing."""
        win = state.hist[-self.grey_window:]
        if not np.isfinite(win).all():
            return None
        return wrap_components(self._grey(win), state.model.z_angles)

    def update(self, state, z, k, mask):
        m = state.model
        state.hist[-1] = z
        if self.wavelet:
            win = state.hist[-self.noise_window:]
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
        w = np.exp(logw - logw.max())
        state.w = w / w.sum()

    def estimate(self, state):
        m, w = state.model, state.w
        x = weighted_mean(state.particles, w, m.x_angles)  # eq. 24
        D = residual(state.particles, x, m.x_angles)
        state.ess_sum += effective_sample_size(w)
        state.steps += 1
        return x, (D.T * w) @ D

    def finish(self, state, info):
        info.update(grey_steps=state.grey_steps, wavelet_steps=state.wavelet_steps,
                    mean_ess=state.ess_sum / max(state.steps, 1),
                    last_sigma=state.sigma.tolist())
