"""Measurement-noise estimation with a Daubechies wavelet (paper 000, §2.3, eq. 13-18).

Inside a sliding window of ``window`` samples a measured signal is a
polynomial of order M (eq. 13, M = 5, by the Weierstrass theorem) plus noise.
A wavelet with ``a > M`` vanishing moments (db6: a = 6) annihilates the
polynomial, so its finest-scale detail coefficients hold noise only (eq. 15-16),
and the noise standard deviation is (eq. 17, Donoho's robust estimator)

    sigma = median(|W_w(s, t_h)|) / 0.6745

Then R_k = diag(sigma_z^2, sigma_v^2, sigma_phi^2) (eq. 18).

Choices made here:

* Only the **interior** finest-scale coefficients are used: the db6
  decomposition high-pass filter (12 taps, from PyWavelets) is correlated with
  the window without boundary extension ("valid" convolution, stride 2). Any
  padding (symmetric, periodic) breaks the polynomial at the window's ends and
  leaks signal into ~5 coefficients at each end. A window of 50 gives
  ``(50 - 12) // 2 + 1 = 20`` coefficients.
* The filter's phase (which of the two polyphase components is kept) does not
  change the noise estimate; we keep the one starting at the window's first sample.
* The detail filter has unit energy, so white noise of std sigma gives
  coefficients of std sigma.

:class:`WaveletNoise` precomputes the (n_coef, window) matrix so that one
estimate for all channels is one small matrix product and a median.
"""

from __future__ import annotations

import numpy as np
import pywt

from replay.util.errors import ReplayError

MAD_SCALE = 0.6745  # eq. 17: median |N(0, 1)|
WINDOW = 50  # the paper's sliding window (§3)
WAVELET = "db6"  # Daubechies, 6 vanishing moments (M = 5 < 6)


def detail_matrix(window: int = WINDOW, wavelet: str = WAVELET) -> np.ndarray:
    """Matrix D (n_coef, window): D @ x = interior finest-scale detail coefficients of x."""
    try:
        hi = np.asarray(pywt.Wavelet(wavelet).dec_hi, float)
    except ValueError as err:
        raise ReplayError(f"wavelet {wavelet!r}: {err}") from None
    L = len(hi)
    if window < L:
        raise ReplayError(f"wavelet window {window} is shorter than the {wavelet} filter ({L} taps)")
    starts = np.arange(0, window - L + 1, 2)
    D = np.zeros((len(starts), window))
    for i, s in enumerate(starts):
        D[i, s : s + L] = hi[::-1]  # convolution: reversed filter
    return D


class WaveletNoise:
    """Noise std per channel from the last ``window`` samples (eq. 17)."""

    def __init__(self, window: int = WINDOW, wavelet: str = WAVELET):
        self.window = int(window)
        self.wavelet = wavelet
        self.D = detail_matrix(self.window, wavelet)

    @property
    def min_samples(self) -> int:
        """Shortest window that still gives one coefficient."""
        return self.D.shape[1] - (self.D.shape[0] - 1) * 2

    def sigma(self, x: np.ndarray) -> np.ndarray:
        """sigma of each column of ``x`` (window, ...) -> (...), from eq. 17.

        A shorter ``x`` (the start of a log) uses the coefficients that fit in it.
        """
        x = np.asarray(x, float)
        n = x.shape[0]
        D = self.D if n == self.window else detail_matrix(n, self.wavelet)
        c = np.sort(np.abs(D @ x.reshape(n, -1)), axis=0)  # median by sort: cheaper than np.median here
        h = len(c) // 2
        med = c[h] if len(c) % 2 else 0.5 * (c[h - 1] + c[h])
        return (med / MAD_SCALE).reshape(x.shape[1:])


def wavelet_sigma(x: np.ndarray, window: int = WINDOW, wavelet: str = WAVELET) -> np.ndarray:
    """Sliding estimate: sigma at every sample k from x[k-window+1 .. k] (NaN before it fills)."""
    x = np.asarray(x, float)
    est = WaveletNoise(window, wavelet)
    if len(x) < window:
        raise ReplayError(f"wavelet window {window} is longer than the series ({len(x)} samples)")
    win = np.lib.stride_tricks.sliding_window_view(x, window, axis=0)  # (n-w+1, ..., window)
    c = np.einsum("cw,k...w->kc...", est.D, win)
    s = np.median(np.abs(c), axis=1) / MAD_SCALE
    out = np.full(x.shape, np.nan)
    out[window - 1 :] = s
    return out
