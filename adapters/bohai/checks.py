"""Checks of the track: velocity from positions, yaw against the course, gyro against attitude."""

from __future__ import annotations

import numpy as np

from replay.util.angles import wrap


def track_velocity(t, p, valid, window=2.0):
    """(n, 2) velocity from positions over ``window`` s centred on each sample.

    NaN where the window holds a masked sample or is shorter than half the window.
    """
    n = len(t)
    lo = np.searchsorted(t, t - window / 2)
    hi = np.searchsorted(t, t + window / 2, side="right") - 1
    bad = np.r_[0, np.cumsum(~valid)]
    span = t[hi] - t[lo]
    ok = (bad[hi + 1] - bad[lo] == 0) & (span >= window / 2)
    v = np.full((n, 2), np.nan)
    v[ok] = (p[hi[ok]] - p[lo[ok]]) / span[ok, None]
    return v


def _speed_check(vel, report) -> dict:
    speed = np.hypot(vel[:, 0], vel[:, 1])
    speed = speed[np.isfinite(speed)]
    if not len(speed):
        return {}
    out = {"median": float(np.median(speed)), "p95": float(np.percentile(speed, 95)), "max": float(speed.max())}
    report.add(
        "info",
        "position",
        len(speed),
        f"position-derived speed median {out['median']:.2f} m/s, 95th percentile "
        f"{out['p95']:.2f} m/s, max {out['max']:.2f} m/s",
    )
    return out


def _yaw_check(yaw, vel, report, min_speed=0.5) -> dict:
    """Agreement of yaw with the course over ground (at speed > ``min_speed``)."""
    speed = np.hypot(vel[:, 0], vel[:, 1])
    sel = np.isfinite(speed) & (speed > min_speed) & np.isfinite(yaw)
    if sel.sum() < 10:
        report.add("info", "attitude", int(sel.sum()), "too few samples at speed to compare yaw with course")
        return {"samples": int(sel.sum())}
    course = np.arctan2(vel[sel, 1], vel[sel, 0])
    signed = wrap(yaw[sel] - course)
    diff = np.abs(signed)
    med = float(np.median(diff))
    out = {
        "samples": int(sel.sum()),
        "median_abs_rad": med,
        "median_rad": float(np.median(signed)),
        "p90_abs_rad": float(np.percentile(diff, 90)),
    }
    report.add(
        "info",
        "attitude",
        int(sel.sum()),
        f"yaw vs course over ground at > {min_speed:g} m/s: median |difference| {med:.3f} rad "
        f"(median signed {out['median_rad']:+.3f} rad)",
    )
    if med > 0.5:
        report.add(
            "flagged", "attitude", int(sel.sum()), f"yaw disagrees with the course over ground (median {med:.2f} rad)"
        )
    return out


def _gyro_check(t, w, att, report, window=1.0) -> dict:
    """Correlation of each gyro axis with the rate of the matching attitude angle.

    Over ``window`` s, wx ~ roll rate, wy ~ pitch rate, wz ~ yaw rate (small
    roll and pitch). Reported, and flagged below 0.3; not a reason to drop.
    """
    k = max(1, int(round(window / np.median(np.diff(t)))))
    if len(t) <= 2 * k:
        return {}
    rate = wrap(att[k:] - att[:-k]) / (t[k:] - t[:-k])[:, None]
    mean = np.cumsum(np.r_[np.zeros((1, 3)), w], axis=0)
    mean = (mean[k + 1 :] - mean[1:-k]) / k  # w averaged over samples i+1 .. i+k
    ok = np.isfinite(rate).all(axis=1) & np.isfinite(mean).all(axis=1)
    if ok.sum() < 10:
        return {}
    corr = [float(np.corrcoef(mean[ok, i], rate[ok, i])[0, 1]) for i in range(3)]
    out = {"wx_roll": corr[0], "wy_pitch": corr[1], "wz_yaw": corr[2]}
    report.add(
        "info",
        "gyro",
        int(ok.sum()),
        "correlation with attitude rates: " + ", ".join(f"{k} {v:.2f}" for k, v in out.items()),
    )
    weak = [k for k, v in out.items() if not v >= 0.3]
    if weak:
        report.add(
            "flagged",
            "gyro",
            int(ok.sum()),
            f"weak correlation with attitude rates ({', '.join(weak)} < 0.3): a gyro axis or "
            f"an attitude angle may not hold what its header says",
        )
    return out


def _forward_check(vf, yaw, vel, report, min_corr=0.5) -> tuple[dict, str | None]:
    """The forward velocity column ``vf`` against the track's speed along the heading
    (``vel . (cos yaw, sin yaw)``): (record, finding or None). A finding (weak correlation, or a
    median difference above max(0.3 m/s, half the median speed)) keeps it from being an input."""
    along = vel[:, 0] * np.cos(yaw) + vel[:, 1] * np.sin(yaw)
    ok = np.isfinite(vf) & np.isfinite(along)
    if ok.sum() < 10:
        return {"samples": int(ok.sum())}, "too few samples to compare with the track's speed"
    d = vf[ok] - along[ok]
    corr = float(np.corrcoef(vf[ok], along[ok])[0, 1]) if np.std(vf[ok]) > 0 and np.std(along[ok]) > 0 else 0.0
    out = {"samples": int(ok.sum()), "corr": corr, "bias": float(np.median(d)), "median_abs": float(np.median(abs(d)))}
    report.add(
        "info",
        "vf",
        out["samples"],
        f"forward velocity vs the track's speed along the heading: correlation {corr:.2f}, "
        f"median difference {out['bias']:+.3f} m/s",
    )
    scale = float(np.median(np.abs(along[ok])))
    if not corr >= min_corr:
        return out, f"correlation {corr:.2f} < {min_corr:g} with the track's speed along the heading"
    if out["median_abs"] > max(0.3, 0.5 * scale):
        return (
            out,
            f"disagrees with the track's speed along the heading (median |difference| {out['median_abs']:.2f} m/s)",
        )
    return out, None
