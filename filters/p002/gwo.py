"""Grey-wolf optimisation (GWO) and the improved GWO (IGWO) of paper 002, §3.1–3.2.

Used as the *resampling* step of a particle filter: the particles are the
wolves, the fitness is the measurement residual (smaller is better), and the
optimiser moves the particles toward the best-fitting ones.

Standard GWO (002, §3.1; Mirjalili et al. 2014), for each wolf X and each of
the three leaders L in {alpha, beta, delta} (the three best wolves):

    D_L = |C_L * X_L - X|,   X_L' = X_L - A_L * D_L,
    A = 2 a r1 - a,  C = 2 r2   (r1, r2 uniform in [0, 1], element-wise, '*' Hadamard)
    X(t+1) = (X_alpha' + X_beta' + X_delta') / 3,   a linear from 2 to 0.

IGWO (002, §3.2) changes two things:

1. the convergence factor (§3.2.1) is the sigmoid :func:`a_sigmoid`;
2. the three leader terms are combined with entropy weights (§3.2.2,
   below): X(t+1) = w~_alpha X_alpha' + w~_beta X_beta' + w~_delta X_delta'.
   Ambiguity: the paper prints ``w~_a X_a + w~_b X_b + w~_d X_d`` with the
   leaders' own positions, which would put every wolf on one point after the
   first iteration; we read X_a, X_b, X_d as the standard GWO candidates
   X_L' = X_L - A_L D_L (as the digest does).

IGWO entropy weights (002, §3.2.2) of the leaders' fitness f_i:

    p_i = (1 / (f_i + eps)) / sum_j 1 / (f_j + eps);  E_i = -p_i log(p_i + eps);
    w*_i = 1 - E_i;  w_i = max(w*_i, xi);  w~_i = w_i / sum_j w_j.

Elitism (002, §3.4.1, proof of condition 1): the alpha, beta and delta wolves
are not moved; only the other wolves are updated, and the leaders of the next
iteration are the three best of the new population (which contains the old
leaders). Hence the best fitness never worsens between iterations; the move
records it and the engine asserts it.

Where it is computed: the move itself (leaders, candidates, entropy weights,
elitism) is the compiled :func:`replay.filters.p002.compiled.swarm`, the
library's only GWO/IGWO move; this module holds what it is given: the
convergence-factor schedule (:func:`schedule`) and the uniforms (:func:`raw_draws`,
:func:`scaled_draws` for PSO). A numpy reading of the move is kept as the test oracle
``tests/oracle_p002.py``.

Observation (not a choice): with the paper's entropy formula, E_i = -p_i log p_i
is at most 1/e, so w*_i = 1 - E_i lies in [0.63, 1] and the floor xi never
binds; the normalised weights stay between about 0.28 and 0.40. The IGWO
leader weighting is therefore close to GWO's 1/3 each; most of the difference
between GWO and IGWO comes from the convergence factor. Nor is it monotone in
the fitness: E peaks at p = 1/e, so the leader order can be inverted, e.g.
f = [1, 1.5, 10] gives w = [0.316, 0.294, 0.390], the worst leader weighing most
(:func:`replay.filters.p002.swarm_kernels.entropy_weights`).
"""

from __future__ import annotations

import numpy as np

from .swarm_kernels import scaled_uniforms
from ..compiled import Kernel

_scaled = Kernel(scaled_uniforms)


def a_linear(t: int, t_max: int, a_start: float = 2.0, a_end: float = 0.0) -> float:
    """Standard GWO convergence factor: linear from ``a_start`` (t = 0) toward ``a_end``."""
    return a_start - (a_start - a_end) * t / t_max


def a_sigmoid(
    t: int,
    t_max: int,
    a_start: float = 2.0,
    a_end: float = 0.0,
    b_start: float = 1.0,
    b_end: float = 0.5,
    form: str = "centred",
) -> float:
    """IGWO nonlinear convergence factor (002, §3.2.1), as we read the garbled formula.

    Printed: a(t) = a_end + (a_start - a_end) / (1 + exp(10 b(t) (2t) / (T_max - 1))),
    b(t) = b_end + (b_start - b_end) (t / T_max)^2. Read literally a(0) = 1, not
    a_start, and a(t) falls fastest at t = 0 — the opposite of the text ("a
    decreases slowly early, quickly late", Fig. 5). We centre the sigmoid:

        a(t) = a_end + (a_start - a_end) / (1 + exp(10 b(t) (2t / (T_max - 1) - 1)))

    so that a(0) ~ a_start, a(T_max - 1) ~ a_end, flat early and steep late.
    The paper gives no b_start, b_end; b(t) as printed runs from b_end at t = 0
    to b_start at T_max, and we take b_end = 0.5, b_start = 1.0 so that the
    sigmoid steepens as the iterations go on.

    ``form="printed"`` evaluates the print literally, s = 10 b(t) 2t / (T_max - 1)
    (a(0) = (a_start + a_end) / 2, fastest fall at t = 0): the ablation of
    docs/reproduction/002.md (the filters' ``a_form`` parameter).
    """
    b = b_end + (b_start - b_end) * (t / t_max) ** 2
    if form == "printed":
        s = 10.0 * b * (2.0 * t) / max(t_max - 1, 1)
    else:
        s = 10.0 * b * (2.0 * t / max(t_max - 1, 1) - 1.0)
    return a_end + (a_start - a_end) / (1.0 + np.exp(s))


def schedule(t_max, improved, a_start=2.0, a_end=0.0, b_start=1.0, b_end=0.5, form="centred") -> np.ndarray:
    """The convergence factor a(t) of iterations t = 0 .. t_max - 1: sigmoid (IGWO; ``form`` as in
    :func:`a_sigmoid`) or linear (GWO)."""
    if improved:
        return np.array([a_sigmoid(t, t_max, a_start, a_end, b_start, b_end, form) for t in range(t_max)])
    return np.array([a_linear(t, t_max, a_start, a_end) for t in range(t_max)])


def as_runs(X, rng, fitness, project):
    """(N, d) wolves, one generator and functions of (N, d) -> the batched forms with M = 1;
    (M, N, d) with M generators (functions of (M, N, d)) unchanged. Returns X, rngs, fitness, project, single."""
    X = np.array(X, dtype=float)
    if X.ndim != 2:
        rngs = list(rng)
        if len(rngs) != len(X):
            raise ValueError("one generator per run of wolves is needed")
        return X, rngs, fitness, project, False
    one = project
    return (X[None], [rng], lambda Y: fitness(Y[0])[None], None if one is None else (lambda Y: one(Y[0])[None]), True)


def raw_draws(rngs, shape):
    """(M, *shape) uint32: 32-bit random integers from each run's generator, two per 64-bit
    output of its bit generator (``random_raw``: half the cost of ``random``)."""
    size = int(np.prod(shape))
    half = (size + 1) // 2
    raw = [g.bit_generator.random_raw(half).view(np.uint32)[:size] for g in rngs]
    out = raw[0][None] if len(raw) == 1 else np.stack(raw)
    return out.reshape((len(rngs),) + tuple(shape))


def uniforms(raw):
    """Uniforms (u + 0.5) 2^-32 in (0, 1) of 32-bit integers u (the GWO and PSO coefficients r1, r2)."""
    r = raw.astype(float)
    r += 0.5
    r *= 2.0**-32
    return r


def scaled_draws(rngs, shape, scales) -> np.ndarray:
    """(M, *shape) uniforms of :func:`draws` (the same draws, the same bits) each times
    ``scales[t, c]`` (shape = (T, C, ...)), in one compiled pass per run
    (:func:`replay.filters.p002.swarm_kernels.scaled_uniforms`): PSO's c1(t) r1 and c2(t) r2."""
    shape = tuple(shape)
    scales = np.ascontiguousarray(scales, dtype=float)
    out = np.empty((len(rngs),) + shape)
    flat = shape[:2] + (-1,)
    for j, g in enumerate(rngs):
        _scaled(raw_draws([g], shape)[0].reshape(flat), scales, out[j].reshape(flat))
    return out


def draws(rngs, shape):
    """One array of uniforms of ``shape`` per run, from the run's own generator: (M, *shape).

    32-bit resolution (:func:`raw_draws`), ample for the random coefficients of
    a swarm step; :mod:`replay.filters.p002.compiled` converts the same integers.
    """
    return uniforms(raw_draws(rngs, shape))
