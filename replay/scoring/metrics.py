"""Metrics beyond RMSE: consistency (NEES, NIS), ATE with alignment, drift, final error, pairs.

Per run (:func:`run_metrics`, on top of :func:`replay.scoring.scorer.score_run`):

* ``ate`` — absolute trajectory error: the position RMSE after aligning the
  estimate to the reference with ``alignment`` (``none``, ``yaw``, ``se3``,
  ``sim3``; :mod:`replay.scoring.align`), over the scored samples (m);
* ``final_err`` — position error at the last scored sample (m);
* ``drift_pct`` — ``final_err`` as a percentage of the distance travelled
  along the reference over the scored samples;
* ``nees`` — mean over steps of the position NEES e' P^-1 e (e the position
  error, P the position block of the covariance; d = number of position axes);
* ``nis`` — mean over steps of y' S^-1 y (filters that record innovations:
  the batched Kalman family; NaN otherwise);
* ``lost`` — the run lost the track: its position error exceeded the task's
  ``lost_threshold`` (m) for ``lost_steps`` consecutive scored samples
  (:class:`replay.tasks.Task`; None when the problem carries no rule). A lost run
  is a result, kept in the means, and counted beside ``diverged``;
* ``diverged`` — the filter's own divergence (non-finite or non-positive
  covariance, :attr:`Estimates.diverged_at`) or a position error beyond the
  ``divergence_threshold`` (m) at any scored sample: the one given, else the task's
  default, ``DIVERGE_FACTOR`` (100) times its lost threshold — an estimate 1.5e7 m off
  with a finite covariance is a divergence, even where too few samples are scored to
  call it lost.

Over a Monte Carlo ensemble of M runs (:func:`consistency`), ``anees`` is the mean over steps of
the average NEES over runs, and its consistency is judged against the band of *that* statistic
(:func:`averaged_band`; Bar-Shalom, Li & Kirubarajan 2001, §5.4.2): the two-sided 95 % band of
the average of M·T chi-square(d) variables, chi2.ppf(0.025 / 0.975, M T d) / (M T), with the
degrees of freedom divided by the time correlation of the per-step averages (an estimation
error is correlated from step to step, so T steps of NEES hold fewer than T independent ones;
the innovations of a consistent filter are white and keep about M·T·d). ``anees_inside`` is a
different statistic, labelled as such: the share of steps whose average over runs lies inside
the one-step band [chi2.ppf(0.025, M d), chi2.ppf(0.975, M d)] / M (about 0.95 when
consistent). NIS likewise with its degrees of freedom (measured components) per step.

Pairs (:func:`paired`): two filters run on the same measurements (common
random numbers, see :mod:`replay.run.evaluation`) are compared run by run; the mean
difference and its 95 % Student-t interval are much tighter than the two
separate intervals suggest.
"""

from __future__ import annotations

import functools

import numpy as np

from replay.scoring import scorer
from replay.scoring.align import align, apply
from replay.scoring.scorer import ci95


def nees(e: np.ndarray, P: np.ndarray) -> np.ndarray:
    """e' P^-1 e for stacked errors ``e`` (..., d) and covariances ``P`` (..., d, d); NaN where e is."""
    e, P = np.asarray(e, float), np.asarray(P, float)
    out = np.full(e.shape[:-1], np.nan)
    ok = np.isfinite(e).all(axis=-1) & np.isfinite(P).all(axis=(-1, -2))
    if ok.any():
        try:
            u = np.linalg.solve(P[ok], e[ok][..., None])[..., 0]
        except np.linalg.LinAlgError:  # a singular P: least squares, every row
            u = lstsq_rows(P[ok], e[ok])
        out[ok] = np.einsum("...i,...i->...", e[ok], u)
    return out


def lstsq_rows(A: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``np.linalg.lstsq(A[i], b[i], rcond=None)[0]`` for every i of stacked ``A`` (k, d, d) and
    ``b`` (k, d), in one compiled loop of numba's ``np.linalg.lstsq`` (the same LAPACK routine,
    ``gelsd``, with lstsq's ``rcond=None`` cut-off; equal bit for bit, tested): ``lstsq`` costs
    15-30 µs a call, and a long run whose covariance is singular somewhere has thousands of
    rows. A non-finite input goes row by row through ``lstsq`` itself, which raises
    ``LinAlgError`` on it."""
    A, b = np.asarray(A, float), np.asarray(b, float)
    if not len(A):
        return np.zeros(b.shape)
    if not (np.isfinite(A).all() and np.isfinite(b).all()):
        return np.stack([np.linalg.lstsq(p, v, rcond=None)[0] for p, v in zip(A, b)])
    out = np.empty(b.shape)
    _lstsq_each()(np.ascontiguousarray(A), np.ascontiguousarray(b), np.finfo(np.float64).eps * max(A.shape[-2:]), out)
    return out


@functools.cache
def _lstsq_each():
    # lazy: start-up, numba measured ~800 ms
    import numba  # noqa: PLC0415 here: scoring without a singular covariance never imports numba (about 0.5 s)

    # lazy: start-up, with numba (above)
    from replay.util import kernel_cache  # noqa: PLC0415, F401  numba's cache of replay's kernels: locked, sealed

    @numba.njit(cache=True)
    def each(A, b, rcond, out):
        for i in range(A.shape[0]):
            out[i] = np.linalg.lstsq(A[i], b[i], rcond)[0]

    return each


def chi2_ppf(q, df):
    """``scipy.stats.chi2.ppf(q, df)`` for 0 < q < 1 (NaN where df <= 0), bit for bit: the
    function it evaluates, 2 gammaincinv(df / 2, q), without importing scipy.stats (0.5-1 s,
    which every campaign paid at start-up; :mod:`scipy.special` costs a fraction of it)."""
    # lazy: start-up, scipy.special measured ~420 ms
    from scipy.special import gammaincinv  # noqa: PLC0415

    df = np.asarray(df, float)
    with np.errstate(invalid="ignore"):
        out = np.where(df > 0, 2 * gammaincinv(df / 2, q), np.nan)
    return out[()] if out.ndim == 0 else out


def chi2_band(dof, runs: int, p: float = 0.95):
    """Two-sided ``p`` band of the average of ``runs`` chi-square(``dof``) variables."""
    dof = np.asarray(dof, float) * runs
    a = (1 - p) / 2
    return chi2_ppf(a, dof) / runs, chi2_ppf(1 - a, dof) / runs


COLLAPSED = 1e4  # a mean NEES/NIS above 1e4 per degree of freedom: the covariance has collapsed


def correlation_factor(series) -> float:
    """How many times the variance of the mean of ``series`` exceeds that of independent samples:
    1 + 2 sum of its lag autocorrelations, summed in pairs while a pair is positive (Geyer's initial
    positive sequence), then divided by 1 - tau / n: centring on the sample mean takes the mean's own
    variance out of every autocovariance, so the sum alone is low by that share. Never below 1 (the band
    is never narrower than for independent steps)."""
    a = np.asarray(series, float)
    a = a[np.isfinite(a)] - np.mean(a[np.isfinite(a)]) if np.isfinite(a).any() else a[:0]
    n = len(a)
    g0 = float(a @ a) / n if n else 0.0
    if n < 4 or g0 <= 0:
        return 1.0
    spec = np.fft.rfft(a, 2 * n)  # the autocovariances at every lag at once
    r = np.fft.irfft(spec * np.conj(spec))[1 : n // 2 + 1] / n / g0
    tau = 1.0
    for i in range(0, len(r) - 1, 2):
        pair = r[i] + r[i + 1]
        if pair <= 0:
            break
        tau += 2 * pair
    return max(tau / (1 - tau / n), 1.0) if tau < n / 2 else float(n)


def averaged_band(dof, runs, series=None, p: float = 0.95):
    """Two-sided ``p`` band of the mean over steps of per-step averages over ``runs[k]`` runs of
    chi-square(``dof[k]``) variables: a weighted sum of chi-squares matched by a scaled chi-square of
    the same mean and variance (exact, M·T·d degrees of freedom, when every step has the same runs and
    dof), its variance multiplied by :func:`correlation_factor` of ``series`` (the per-step averages,
    each divided by its dof) and by (t / z)^2, Student's t quantile with n / tau - 1 degrees of freedom
    over the normal one (the correlation is estimated from the series itself: 1.09 for T = 100 steps
    with tau = 3). Returns (lo, hi, effective degrees of freedom)."""
    dof, runs = np.asarray(dof, float), np.asarray(runs, float)
    n = len(dof)
    mean = float(dof.mean())
    var = float(np.sum(2 * dof / runs)) / n**2
    if series is not None and n > 1:  # the correlation estimated from the series: its own uncertainty
        tau = correlation_factor(series)  # widens the band as Student's t does (n / tau - 1 dof)
        # lazy: start-up, scipy.special measured ~420 ms
        from scipy.special import ndtri, stdtrit  # noqa: PLC0415

        nu = max(n / tau - 1, 1.0)
        var *= tau * (float(stdtrit(nu, 1 - (1 - p) / 2)) / float(ndtri(1 - (1 - p) / 2))) ** 2
    h = 2 * mean**2 / var
    a = (1 - p) / 2
    return mean * float(chi2_ppf(a, h)) / h, mean * float(chi2_ppf(1 - a, h)) / h, h


def consistency(values: np.ndarray, dof, prefix: str = "anees") -> dict:
    """Ensemble consistency of per-run, per-step NEES or NIS ``values`` (M, n).

    ``dof`` is a scalar or (n,) per step (0 where the statistic is undefined).
    Returns ``<prefix>`` (mean over steps of the average over runs), the band of that mean
    ``<prefix>_lo``/``_hi`` (:func:`averaged_band`: runs x steps degrees of freedom, corrected for
    the time correlation), ``<prefix>_inside`` the share of steps whose average lies in its
    one-step band (a different statistic), and
    ``<prefix>_flag``: ``consistent`` (the mean lies in its band), ``optimistic``
    (above: the covariance is too small), ``pessimistic`` (below) or ``collapsed``.

    *Collapsed*: the mean exceeds ``COLLAPSED`` times the degrees of freedom (errors of
    more than 100 standard deviations on average), is negative (a covariance that is not
    positive definite) or is not finite. The covariance then
    says nothing about the error; its value (1e+235 has been seen) is not a measurement of
    anything, so ``<prefix>`` is set to NaN and only the flag remains.
    """
    v = np.asarray(values, float)
    dof = np.broadcast_to(np.asarray(dof, float), v.shape[-1:])
    runs = np.isfinite(v).sum(axis=0)
    use = (runs > 0) & (dof > 0)
    out = {
        prefix: np.nan,
        f"{prefix}_lo": np.nan,
        f"{prefix}_hi": np.nan,
        f"{prefix}_inside": np.nan,
        f"{prefix}_flag": "",
    }
    if not use.any():
        return out
    with np.errstate(invalid="ignore"):
        avg = np.nansum(v[:, use], axis=0) / runs[use]
    lo, hi = chi2_band(dof[use], runs[use])
    d0 = float(np.median(dof[use]))
    blo, bhi, _ = averaged_band(dof[use], runs[use], avg / dof[use])
    with np.errstate(all="ignore"):
        mean = float(avg.mean())
    out.update(
        {
            prefix: mean,
            f"{prefix}_lo": float(blo),
            f"{prefix}_hi": float(bhi),
            f"{prefix}_inside": float(np.mean((avg >= lo) & (avg <= hi))),
        }
    )
    if not np.isfinite(mean) or mean > COLLAPSED * d0 or mean < 0:  # < 0: P not positive definite
        out.update({prefix: np.nan, f"{prefix}_flag": "collapsed"})
    else:
        out[f"{prefix}_flag"] = "optimistic" if mean > bhi else "pessimistic" if mean < blo else "consistent"
    return out


def ate(est: np.ndarray, ref: np.ndarray, alignment: str = "none") -> float:
    """Position RMSE after aligning ``est`` (n, d) onto ``ref`` (rows with NaN skipped)."""
    ok = np.isfinite(est).all(axis=1) & np.isfinite(ref).all(axis=1)
    a, b = est[ok], ref[ok]
    if not len(a):
        return float("nan")
    R, t, c = align(a, b, alignment)
    e = apply(R, t, c, a) - b
    return float(np.sqrt(np.mean(np.sum(e**2, axis=1))))


def path_length(p: np.ndarray) -> float:
    """Distance travelled along the finite rows of ``p`` (n, d)."""
    q = p[np.isfinite(p).all(axis=1)]
    return float(np.linalg.norm(np.diff(q, axis=0), axis=1).sum()) if len(q) > 1 else 0.0


def quat_angle(q_est: np.ndarray, q_ref: np.ndarray) -> np.ndarray:
    """Rotation angle (rad) between unit quaternions (..., 4) [w, x, y, z]: |log(q_ref^-1 q_est)|.

    2 atan2(|v|, |w|) of the relative quaternion: accurate near 0 (unlike 2 acos|w|).
    """
    a, b = np.asarray(q_est, float), np.asarray(q_ref, float)
    w = np.einsum("...i,...i->...", a, b)  # real part of conj(b) a
    v = b[..., :1] * a[..., 1:] - a[..., :1] * b[..., 1:] - np.cross(b[..., 1:], a[..., 1:])
    return 2.0 * np.arctan2(np.linalg.norm(v, axis=-1), np.abs(w))


def pose_errors(p_est, q_est, p_ref, q_ref) -> dict:
    """Position error norm (m) and attitude error angle (rad) of every pose, with their RMSE."""
    dp = np.linalg.norm(np.asarray(p_est, float) - p_ref, axis=-1)
    da = quat_angle(q_est, q_ref)
    return {
        "position": dp,
        "attitude": da,
        "pos_rmse": float(np.sqrt(np.mean(dp**2))),
        "att_rmse": float(np.sqrt(np.mean(da**2))),
    }


def lost_track(err_norm: np.ndarray, threshold: float | None, steps: int):
    """True when ``err_norm`` (n,) exceeds ``threshold`` for ``steps`` consecutive scored samples
    (NaN samples are not scored and skipped; a run scored on fewer samples needs all of them above);
    None when there is no threshold."""
    if threshold is None:
        return None
    e = err_norm[np.isfinite(err_norm)]
    if not len(e):
        return False
    edges = np.diff(np.concatenate([[0], (e > threshold).astype(np.int8), [0]]))
    longest = (np.flatnonzero(edges == -1) - np.flatnonzero(edges == 1)).max(initial=0)
    return bool(longest >= min(int(steps), len(e)))


def share_above(err: np.ndarray, threshold: float) -> float:
    """The share of the steps of one run whose error norm (rows of ``err``, (n, d)) exceeds ``threshold``; a NaN
    step counts as not above, and every step counts in the denominator."""
    return float(np.mean(np.linalg.norm(err, axis=1) > threshold))


def run_metrics(
    problem, est, alignment: str = "none", divergence_threshold: float | None = None, errors: dict | None = None
):
    """Per-run metrics (module docstring) and the per-step series ``nees``, ``nis``, ``nis_dof``;
    ``errors``: the run's :func:`replay.scoring.scorer.errors`, when computed already."""
    errors = scorer.errors(problem, est) if errors is None else errors
    m = scorer.score_run(problem, est, errors)
    err = errors["position"]
    pos = list(problem.position_index)
    P = est.P[:, pos][:, :, pos]
    nees_k = nees(err, P)
    m["nees_dof"] = len(pos)  # degrees of freedom of the position NEES (the task's position axes)
    ok = np.isfinite(err).all(axis=1)
    est_pos = np.where(ok[:, None], est.x[:, pos], np.nan)
    ref = np.where(ok[:, None], problem.truth_position, np.nan)
    m["ate"] = ate(est_pos, ref, alignment)
    last = np.flatnonzero(ok)
    m["final_err"] = float(np.linalg.norm(err[last[-1]])) if len(last) else float("nan")
    dist = path_length(ref)
    m["drift_pct"] = 100.0 * m["final_err"] / dist if dist > 0 else float("nan")
    nis_k = np.asarray(est.info.get("nis", np.full(len(err), np.nan)), float)
    nis_dof = np.asarray(est.info.get("nis_dof", np.zeros(len(err), int)))
    m["nees"] = float(np.nanmean(nees_k)) if np.isfinite(nees_k).any() else float("nan")
    m["nis"] = float(np.nanmean(nis_k)) if np.isfinite(nis_k).any() else float("nan")
    if divergence_threshold is None:  # the task's default: far beyond a lost track (replay.tasks.DIVERGE_FACTOR)
        divergence_threshold = getattr(problem, "divergence_threshold", None)
    big = divergence_threshold is not None and np.nanmax(np.linalg.norm(err, axis=1), initial=0) > divergence_threshold
    m["diverged"] = bool(est.diverged or big)
    m["lost"] = (
        None
        if m["diverged"]
        else lost_track(
            np.linalg.norm(err, axis=1), getattr(problem, "lost_threshold", None), getattr(problem, "lost_steps", 10)
        )
    )
    m["diverged_at"] = est.diverged_at
    return m, {"nees": nees_k, "nis": nis_k, "nis_dof": nis_dof}


def paired(a, b) -> dict:
    """Run-by-run comparison of a metric for two filters on the same runs: mean of a - b, 95 % interval.

    ``a``, ``b``: per-run values in run order (NaN pairs skipped). ``a_better`` is
    the fraction of runs where a < b (lower is better for errors).
    """
    a, b = np.asarray(a, float), np.asarray(b, float)
    ok = np.isfinite(a) & np.isfinite(b)
    d = a[ok] - b[ok]
    return {
        "n": int(ok.sum()),
        "diff": float(d.mean()) if len(d) else float("nan"),
        "diff_ci95": ci95(d),
        "a_better": float(np.mean(d < 0)) if len(d) else float("nan"),
    }


def stacked_errors(errors: list[dict], key: str = "position") -> np.ndarray:
    """One filter's per-run ``key`` errors (a dict per run, as ``Evaluation.results[i].errors``) as one array
    (runs, steps, d)."""
    return np.stack([np.asarray(e[key], float) for e in errors])


def axis_errors(errors: list[dict], axes, key: str = "position") -> dict:
    """Per-run absolute errors of each axis, ``{axes[j]: |e_j|}`` (runs, steps) of the j-th component of ``key``
    (:func:`stacked_errors`); the RMSE over runs at each step is the same as of the signed errors."""
    e = np.abs(stacked_errors(errors, key))
    return {a: e[:, :, j] for j, a in enumerate(axes)}


def window_growth(err: np.ndarray, early, late, invalid=None) -> np.ndarray:
    """Per run: the RMS error over the steps ``late`` = (start, stop) minus over ``early`` (0-based, stop
    excluded); positive where the error grows over the run. ``err``: (runs, steps), or (runs, steps, d) for the
    norm over d; NaN for the runs where ``invalid`` (e.g. diverged) is true."""
    e = np.linalg.norm(err, axis=-1) if np.ndim(err) == 3 else np.array(err, float)
    if invalid is not None:
        e[np.asarray(invalid, bool)] = np.nan

    def rms(window):
        return np.sqrt(np.mean(e[:, slice(*window)] ** 2, axis=1))

    with np.errstate(invalid="ignore"):
        return rms(late) - rms(early)
