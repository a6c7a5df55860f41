"""GM(1,1) grey prediction (paper 000, §2.2, eq. 7-12).

Given the last ``n`` measurements of one channel, z0 = {z0(1), ..., z0(n)} (eq. 7):

    eq. 8   z1(k) = sum_{i<=k} z0(i)                       (accumulated series)
    eq. 9   dz1/dt + a z1 = b                              (grey differential equation)
    eq. 10  [a, b]' = (B'B)^-1 B'Y,  B = [-Z1(k), 1],  Y = z0(k),  k = 2..n,
            Z1(k) = alpha z1(k) + (1 - alpha) z1(k-1)      (background value, alpha = 0.5)
    eq. 11  z1^(k+1) = (z0(1) - b/a) e^(-a k) + b/a
    eq. 12  z0^(k+1) = z1^(k+1) - z1^(k) = (1 - e^a) (z0(1) - b/a) e^(-a k)

Choices made here (the paper is silent or ambiguous):

* **Time response.** Eq. 11-12 use the continuous solution of eq. 9, which is
  biased for the very series GM(1,1) models: on an exact exponential
  z0(k) = c r^k the least squares of eq. 10 is exact (a = -2(r-1)/(r+1)) but
  e^(-a) != r. The default ``response="discrete"`` uses the time response of
  the discretised equation that eq. 10 actually fits,
  z0(k) + a Z1(k) = b with Z1 the background value, solved for the next step:

      z0^(n+1) = (b - a z1(n)) / (1 + alpha a)

  It is exact for exponential (and constant) series and agrees with eq. 12 to
  first order in ``a``. ``response="continuous"`` is eq. 12 as derived from
  eq. 11, z1^(n+1) - z1^(n) = (1 - e^a)(z0(1) - b/a) e^(-a n).
  ``response="printed"`` is eq. 12 with the factor the paper prints,
  (1 - e^-a)(z0(1) - b/a) e^(-a n): since (1 - e^-a) = -e^-a (1 - e^a), it is
  the continuous response times -e^-a, i.e. about the *negated* prediction for
  the small |a| of these windows (limit -b at a = 0); with the conditioning shift
  c it lands near -(z + 2c). Kept only to show what the print does; the
  printed factor is taken for a typesetting slip.
* **Conditioning shift** (the digest's request). GM(1,1) fits an exponential
  and is ill-conditioned for data near zero or negative (depth at the surface,
  pitch around 0). When the window's minimum is below ``floor``, the window is
  shifted by the constant ``c = max(floor, shift_ratio * span) - min`` before
  fitting and the prediction is shifted back by ``-c``. A shifted series far
  from zero relative to its span makes GM(1,1) behave like a smooth local
  trend extrapolation (``shift_ratio = 100``: on a straight ramp the one-step
  error is about 1/40 of a step; with 10 it is 1/4 of a step). Constant
  series stay exact (a = 0, b = the constant).
* ``a = 0`` (a constant series) is handled by the discrete response without
  dividing by ``a``; the continuous response takes its limit ``b`` (the
  printed one ``-b``). A constant window predicts itself under every response.

All functions work along axis 0 on arrays of shape (n, ...): several channels
(or Monte Carlo runs) are predicted at once.
"""

from __future__ import annotations

import numpy as np

from replay.util.errors import ReplayError

ALPHA = 0.5  # background weight of eq. 10 ("generally 0.5")
RESPONSES = ("discrete", "continuous", "printed")  # time response (module docstring)


def gm11_fit(z0: np.ndarray, alpha: float = ALPHA):
    """Least-squares grey parameters ``(a, b)`` of eq. 10 for the series along axis 0."""
    z0 = np.asarray(z0, float)
    n = z0.shape[0]
    if n < 3:
        raise ReplayError(f"GM(1,1) needs at least 3 samples (got {n})")
    z1 = np.cumsum(z0, axis=0)  # eq. 8
    Z = alpha * z1[1:] + (1.0 - alpha) * z1[:-1]  # background value, k = 2..n
    Y = z0[1:]
    m = n - 1
    sZ, sY = Z.sum(axis=0), Y.sum(axis=0)
    # eq. 10 in closed form (centred sums, for accuracy)
    Zc, Yc = Z - sZ / m, Y - sY / m
    var = (Zc * Zc).sum(axis=0)
    cov = (Zc * Yc).sum(axis=0)
    with np.errstate(divide="ignore", invalid="ignore"):
        a = np.where(var > 0, -cov / np.where(var > 0, var, 1.0), 0.0)
    b = (sY + a * sZ) / m
    return a, b


def gm11_predict(
    z0: np.ndarray,
    alpha: float = ALPHA,
    response: str = "discrete",
    floor: float | None = 1.0,
    shift_ratio: float = 100.0,
) -> np.ndarray:
    """One-step GM(1,1) prediction z0^(n+1) of the series along axis 0 (eq. 7-12).

    ``floor`` and ``shift_ratio`` set the conditioning shift (module docstring);
    ``floor=None`` disables it.
    """
    z0 = np.asarray(z0, float)
    return GreyPredictor(z0.shape[0], alpha, response, floor, shift_ratio)(z0)


class GreyPredictor:
    """:func:`gm11_predict` for windows of a fixed length ``n``, with the sums of
    eq. 10 precomputed as one matrix (one product per call: the GPF calls it every step)."""

    def __init__(
        self,
        n: int,
        alpha: float = ALPHA,
        response: str = "discrete",
        floor: float | None = 1.0,
        shift_ratio: float = 100.0,
    ):
        if n < 3:
            raise ReplayError(f"GM(1,1) needs at least 3 samples (got {n})")
        if response not in RESPONSES:
            raise ReplayError(f"GM(1,1) response must be one of {', '.join(RESPONSES)} (got {response!r})")
        self.n, self.alpha, self.response = n, float(alpha), response
        self.floor, self.shift_ratio = floor, float(shift_ratio)
        m = n - 1
        S = np.tril(np.ones((n, n)))  # z1 = S z0 (eq. 8)
        A = alpha * S[1:] + (1.0 - alpha) * S[:-1]  # background Z1(k), k = 2..n
        E = np.eye(n)[1:]  # Y = z0(k), k = 2..n
        C = np.eye(m) - 1.0 / m  # centring
        # rows: centred Z (m), centred Y (m), mean Z, mean Y, z1(n)
        self.M = np.vstack([C @ A, C @ E, A.mean(axis=0), E.mean(axis=0), np.ones(n)])
        self.m = m

    def __call__(self, z0: np.ndarray) -> np.ndarray:
        z0 = np.asarray(z0, float)
        lo, hi = z0.min(axis=0), z0.max(axis=0)
        if self.floor is not None:
            shift = (lo < self.floor) * (np.maximum(self.floor, self.shift_ratio * (hi - lo)) - lo)
        else:
            shift = np.zeros_like(lo)
        x = z0 + shift
        r = self.M @ x
        m = self.m
        Zc, Yc = r[:m], r[m : 2 * m]
        var = (Zc * Zc).sum(axis=0)
        const = hi == lo  # a constant series predicts itself, bit for bit
        a = -(Zc * Yc).sum(axis=0) / np.where(const, 1.0, var)  # eq. 10
        b = r[2 * m + 1] + a * r[2 * m]
        if self.response == "discrete":
            pred = (b - a * r[2 * m + 2]) / (1.0 + self.alpha * a)
        else:  # eq. 12 (derived: 1 - e^a, limit b; printed: 1 - e^-a, limit -b)
            small = np.abs(a) < 1e-12
            a_s = np.where(small, 1.0, a)
            if self.response == "continuous":
                factor, limit = 1.0 - np.exp(a_s), b
            else:
                factor, limit = 1.0 - np.exp(-a_s), -b
            pred = np.where(small, limit, factor * (x[0] - b / a_s) * np.exp(-a_s * self.n))
        return np.where(const, z0[-1], pred - shift)
