"""Measurement-noise models that any task or simulator can use.

:class:`Glint` is the glint noise of paper 003 (eq. 7–10): a two-component
Gaussian mixture, a Gaussian core with probability 1 − ε and a heavy tail with
probability ε,

    p(e) = (1 − ε) N(e; μ₁, P₁) + ε N(e; μ₂, P₂)                          (8)
    μ = E[e] = (1 − ε) μ₁ + ε μ₂                                            (9)
    P = cov(e) = (1 − ε)(P₁ + μ₁μ₁ᵀ) + ε(P₂ + μ₂μ₂ᵀ) − μμᵀ                  (10, corrected)

The paper's eq. (10) prints ``(1 − ε)μ₁μ₁ᵀ + εμ₂μ₂ᵀ − μμᵀ``: it omits P₁ and
P₂ (for the zero-mean components it uses, that would make the covariance
zero). :attr:`Glint.cov` is the mixture's true covariance, as above.

In paper 003, ε is called an "influence factor" and printed as 0.75 (§4.1);
it is a different quantity from the weight exponent α of eq. 27, which the
paper also prints as 0.75 (§4.2): see :mod:`replay.filters.p003.wfpf`.
"""

from __future__ import annotations

import numpy as np
from scipy.linalg import solve_triangular
from scipy.special import logsumexp

from replay.util.kernels import LOG_2PI, gauss_logpdf
from replay.util.linalg import require_spd
from replay.util.errors import ReplayError
from replay.util.covariance import Covariance, as_matrix, diagonal  # noqa: F401 — declared here before


class Glint:
    """Two-component Gaussian mixture noise (paper 003, eq. 7–10).

    ``eps`` (ε, the glint strength, default 0.75 as printed in 003 §4.1) is the
    probability of the heavy-tailed component ``N(mu2, P2)``; ``N(mu1, P1)`` is
    the thermal (core) component. Means default to zero.
    """

    def __init__(self, P1, P2, eps: float = 0.75, mu1=None, mu2=None):
        eps = float(eps)
        if not 0.0 <= eps <= 1.0:
            raise ReplayError(f"glint probability eps={eps:g} must lie in [0, 1]")
        self.eps = eps
        self.P1 = require_spd(P1, "glint P1")
        self.P2 = require_spd(P2, "glint P2")
        if self.P1.shape != self.P2.shape:
            raise ReplayError(f"glint P1 {self.P1.shape} and P2 {self.P2.shape} differ in shape")
        d = len(self.P1)
        self.mu1 = np.zeros(d) if mu1 is None else np.asarray(mu1, float).reshape(d)
        self.mu2 = np.zeros(d) if mu2 is None else np.asarray(mu2, float).reshape(d)
        self._L = (np.linalg.cholesky(self.P1), np.linalg.cholesky(self.P2))
        self._diag = not (
            np.any(self.P1 - np.diag(np.diagonal(self.P1))) or np.any(self.P2 - np.diag(np.diagonal(self.P2)))
        )
        self._logdet = (2 * np.log(np.diag(self._L[0])).sum(), 2 * np.log(np.diag(self._L[1])).sum())

    @property
    def dim(self) -> int:
        return len(self.P1)

    @property
    def mean(self) -> np.ndarray:
        """Eq. (9): μ = (1 − ε) μ₁ + ε μ₂."""
        return (1 - self.eps) * self.mu1 + self.eps * self.mu2

    @property
    def cov(self) -> np.ndarray:
        """The mixture covariance (eq. 10 with the P₁, P₂ terms the paper omits)."""
        m = self.mean
        return (
            (1 - self.eps) * (self.P1 + np.outer(self.mu1, self.mu1))
            + self.eps * (self.P2 + np.outer(self.mu2, self.mu2))
            - np.outer(m, m)
        )

    def excess_kurtosis(self) -> np.ndarray:
        """Excess kurtosis E[(e − μ)⁴] / var² − 3 of each axis' marginal (0 for a Gaussian, > 0 for a heavy tail).

        Component k (weight w_k, mean offset d_k = μ_k − μ, variance v_k) adds w_k (d_k⁴ + 6 d_k² v_k + 3 v_k²)
        to the fourth central moment and w_k (v_k + d_k²) to the variance; for zero means and σ₂ = r σ₁ that is
        3((1 − ε) + ε r⁴) / ((1 − ε) + ε r²)² − 3 (0.48 at the printed r = 2, ε = 0.75 of 003 §4.1)."""
        w = np.array([[1 - self.eps], [self.eps]])
        v = np.stack([np.diagonal(self.P1), np.diagonal(self.P2)])
        d = np.stack([self.mu1, self.mu2]) - self.mean
        var = np.sum(w * (v + d**2), axis=0)
        return np.sum(w * (d**4 + 6 * d**2 * v + 3 * v**2), axis=0) / var**2 - 3

    def sample(self, rng: np.random.Generator, n: int) -> np.ndarray:
        """``n`` draws, shape (n, dim): component 2 with probability ε."""
        glint = rng.random(n) < self.eps
        e = rng.standard_normal((n, self.dim))
        core = self.mu1 + e @ self._L[0].T
        tail = self.mu2 + e @ self._L[1].T
        return np.where(glint[:, None], tail, core)

    def logpdf(self, e: np.ndarray) -> np.ndarray:
        """log p(e) for residuals ``e`` of shape (..., dim) (log-sum-exp of the two components)."""
        e = np.asarray(e, float)
        terms = []
        for w, mu, L, logdet in (
            (1 - self.eps, self.mu1, self._L[0], self._logdet[0]),
            (self.eps, self.mu2, self._L[1], self._logdet[1]),
        ):
            if w == 0.0:
                continue
            if self._diag:
                u = (e - mu) / np.diagonal(L)
            else:
                u = solve_triangular(L, (e - mu).reshape(-1, self.dim).T, lower=True, check_finite=False).T.reshape(
                    e.shape
                )
            terms.append(np.log(w) + gauss_logpdf(np.sum(u * u, axis=-1) + logdet, self.dim * LOG_2PI))
        return terms[0] if len(terms) == 1 else logsumexp(np.stack(terms), axis=0)
