"""Strong-tracking cubature Kalman filter (STCKF), paper 002 §2.2.2.

A CKF (:class:`replay.filters.sigma.CKF`) whose measurement update scales the
innovation and cross covariance sums by a fading factor lambda >= 1:

    P_zz^lambda = lambda (1/2n sum Z_i Z_i' - z^ z^') + R          (002, §2.2.2, last display)
    P_xz^lambda = lambda (1/2n sum X_i Z_i' - x^ z^')

    lambda_{k+1} = max(1, lambda_0),  lambda_0 = tr(N_{k+1}) / tr(M_{k+1})
    N_{k+1} = V_{k+1} - H Q_k H' - beta R_{k+1}
    M_{k+1} = H Phi H'                         (see the choice below)
    V_1 = e_1 e_1',  V_{k+1} = (rho V_k + e_{k+1} e_{k+1}') / (1 + rho)
    e_{k+1} = z_{k+1} - h(x^_{k+1|k})

with forgetting factor rho = 0.95 (0 < rho <= 1) and weakening factor beta = 1.2
(beta >= 1); H and Phi are the Jacobians of h (at x^_{k+1|k}) and f (at x^_k). lambda is
computed by :func:`replay.filters.p002.compiled_util.fading_factor`, the kernel of the
STCPF's particles too (one text: compiled, or run as Python with ``NUMBA_DISABLE_JIT=1``).

Choices where the paper is ambiguous (each configurable):

* ``m_form="propagated"`` (default): M = H Phi P_k Phi' H', the form of the
  strong tracking filter the paper builds on (Zhou & Frank 1996; Zhang et al.
  2019): H Phi H' as printed adds a measurement-squared quantity to a
  state-free one and is not dimensionally consistent. ``m_form="printed"``
  uses H Phi H' literally.
* ``scale_prior=True`` (default): the posterior covariance is
  P = lambda P_{k+1|k} - K P_zz^lambda K'. Scaling only P_zz and P_xz (as
  printed) while subtracting K S K' from the unscaled prior makes P indefinite
  whenever lambda is large; scaling the prior too is exactly the Kalman update
  with the faded prior lambda P_{k+1|k} for a linear h (Zhang et al. 2019).
  ``scale_prior=False`` follows the print (P = P_{k+1|k} - K S K').
* ``form="innovation"`` (default): lambda acts on the cubature sums of P_zz
  and P_xz (and the prior, ``scale_prior``), as printed. ``form="classic"``:
  the classic strong-tracking prediction P_{k+1|k} = lambda F P F' + Q (Zhou &
  Frank 1996), Q left unscaled: the cubature estimate of F P F' (the predicted
  covariance minus Q) is scaled, fresh cubature points are drawn from the new
  prior and the update is the CKF's (:meth:`STCKF.classic`). The same lambda
  (``m_form``, ``rho``, ``beta``); ``scale_prior=False`` is refused with it.
* Missing measurement components: lambda is computed from the measured
  components; V restarts (V = e e') whenever the set of measured components
  changes.
* ``repair=False`` (default): a posterior covariance that is not positive
  definite makes the next step's cubature points fail, and the run counts as
  diverged. The print (``m_form="printed"``, ``scale_prior=False``) needs a
  repair to run at all: lambda = tr(N) / tr(H Phi H') does not scale with the
  state's uncertainty (tr(H Phi H') is O(1) in the range row and O(1/r^2) in the
  angle rows; on the sonar model lambda > 1 in about 60 % of the updates, up to
  ~60) and P_{k+1|k} - K S K' turns indefinite. ``repair=True`` symmetrises
  it and floors its eigenvalues at 1e-12 max(1, largest) (the repair of the
  particle filters' kernels, :func:`replay.filters.p002.compiled_util.factor`),
  counted in ``info["covariance_repairs"]``. With ``scale_prior=True`` the printed
  M multiplies P by lambda every step until it overflows: no repair helps.

``info``: ``lambda`` (every update's fading factor), ``lambda_mean``,
``lambda_gt1`` (updates with lambda > 1), ``covariance_repairs``.

When lambda = 1 the update is the CKF's, bit for bit.
"""

from __future__ import annotations

import numpy as np

from replay.filters.case import Case
from replay.util.angles import residual
from replay.util.errors import ReplayError
from replay.util.params import Param
from replay.model import remap_indices

from ..sigma import CKF
from . import compiled_util


STCKF_PARAMS = (
    Param(
        "rho",
        float,
        0.95,
        "STCKF forgetting factor of the innovation average V (002 §2.2.2)",
        low=0.0,
        high=1.0,
        low_open=True,
    ),
    Param("beta", float, 1.2, "STCKF weakening factor (002 §2.2.2)", low=1.0),
    Param(
        "m_form",
        str,
        "propagated",
        "M of the fading factor: H Phi P Phi' H' (propagated) or H Phi H' as printed",
        choices=("propagated", "printed"),
    ),
    Param("scale_prior", bool, True, "scale the prior covariance by the fading factor too (false: as printed)"),
)
FORM = Param(
    "form",
    str,
    "innovation",
    "where the fading factor acts: on the cubature sums of P_zz and P_xz "
    "(and the prior, scale_prior) as 002 prints (innovation), or the classic strong-tracking prior "
    "lambda F P F' + Q with fresh cubature points (classic)",
    choices=("innovation", "classic"),
)
REPAIR = Param(
    "repair",
    bool,
    False,
    "repair a posterior covariance that is not positive definite (eigenvalue "
    "floor) instead of counting the run as diverged",
)


class STCKF(CKF):
    """CKF with the strong-tracking fading factor of 002 §2.2.2 (rho = 0.95, beta = 1.2)."""

    name = "stckf"
    CASE = Case(params={"rho": 0.9})
    PARAMS = CKF.PARAMS + STCKF_PARAMS + (REPAIR, FORM)

    def check(self):
        if self.form == "classic" and not self.scale_prior:
            raise ReplayError(
                f"{self.owner()}: scale_prior=false applies to form=innovation only (the classic "
                "form scales F P F', not the innovation)"
            )

    def start(self, state, x0, P0):
        super().start(state, x0, P0)
        state.V, state.V_mask, state.lambdas, state.repairs = None, None, [], 0

    def predict(self, state, k):
        state.x_prev, state.P_prev = state.x, state.P
        super().predict(state, k)

    def fading(self, state, z, k, mask, R):
        """The fading factor (:func:`replay.filters.p002.compiled_util.fading_factor`, the kernel of
        the STCPF's particles too) of the innovation z - h(x^-); V kept in ``state``."""
        m = state.model
        angles = m.z_angles
        zh = m.h(state.x, k)
        H = m.H(state.x, k)
        if mask is not None:
            zh, z, H = zh[mask], z[mask], H[mask]
            angles = remap_indices(angles, mask)
        key = None if mask is None else tuple(mask)
        fresh = state.V is None or key != state.V_mask
        if fresh:
            state.V, state.V_mask = np.empty((len(zh), len(zh))), key
        e = np.ascontiguousarray(residual(z, zh, angles), dtype=float)
        work = [np.empty(H.shape) for _ in range(3)]
        lam = compiled_util.fading_factor(
            state.V,
            e,
            fresh,
            *(
                np.ascontiguousarray(a, dtype=float)
                for a in (H, m.F(state.x_prev, k), state.P_prev, m.process_cov(k), R)
            ),
            compiled_util.Fading.of(self),
            tuple(work),
        )
        state.lambdas.append(lam)
        return lam

    def update(self, state, z, k, mask):
        y, Pzz, Pxz, R = self.innovation(state, z, k, mask)
        lam = self.fading(state, z, k, mask, R)
        if lam == 1.0:
            self.correct(state, y, Pzz + R, Pxz)
            return
        if self.form == "classic":
            self.classic(state, z, k, mask, lam)
            return
        with np.errstate(over="ignore", invalid="ignore"):  # an overflow is this run's divergence, counted
            if self.scale_prior:
                state.P = lam * state.P
            S, Pxz = lam * Pzz + R, lam * Pxz
        self.correct(state, y, S, Pxz)
        if self.repair:
            L = np.empty_like(state.P)
            if compiled_util.factor(state.P, L) and np.isfinite(L).all():
                state.P = L @ L.T
                state.repairs += 1

    def classic(self, state, z, k, mask, lam):
        """The classic strong-tracking prediction lambda F P F' + Q (Zhou & Frank 1996): the fading factor
        scales the propagated covariance (the cubature estimate P_{k+1|k} - Q), not Q; the innovation
        is recomputed from fresh cubature points of that prior and used unscaled."""
        Q = state.model.process_cov(k)
        with np.errstate(over="ignore", invalid="ignore"):
            state.P = lam * (state.P - Q) + Q
        y, Pzz, Pxz, R = self.innovation(state, z, k, mask)
        self.correct(state, y, Pzz + R, Pxz)

    def finish(self, state, info):
        lam = np.asarray(state.lambdas)
        info["lambda"] = lam
        info["lambda_mean"] = float(lam.mean()) if len(lam) else float("nan")
        info["lambda_gt1"] = int((lam > 1.0).sum())
        info["covariance_repairs"] = state.repairs
