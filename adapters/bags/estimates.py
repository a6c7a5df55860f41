"""Recorded estimates of a bag: ``[estimates]`` entries -> :class:`replay.frame.RecordedEstimate`.

Each estimate keeps its own stamps (not merged into the frame's time axis), its
positions, its orientation (unit quaternions x, y, z, w) and its position
covariance when the message carries one (PoseWithCovarianceStamped and Odometry:
the 3 x 3 position block of ``pose.covariance``; NavSatFix: ``position_covariance``
unless its type is UNKNOWN). What is done to the samples is in the frame report:

* dropped — a pose with a non-finite position or quaternion, a NavSatFix without a
  fix (status < 0) or with impossible coordinates;
* repaired — a quaternion whose norm is off by more than 1e-6 (and at most 1e-3),
  normalised;
* masked — a covariance that is all zero or not finite (unknown): no NEES there.

Refused, one line naming the file and topic: an estimate whose quaternion norm is
off by more than 1e-3 (a quaternion that is exactly zero on every message means
"no orientation recorded" and is accepted as such), duplicate or decreasing stamps,
no usable pose, and stamps (shifted by the entry's ``t_offset``) that do not
overlap the reference's span.
"""

from __future__ import annotations

import numpy as np

from replay.frame import RecordedEstimate, Report
from replay.util.errors import DataError

from .. import rosmsg
from ..mapping import ESTIMATE_KINDS, Mapping
from . import sources
from .recording import Recording

REPAIR_TOL = 1e-6  # quaternion norm error normalised silently below this, repaired (counted) above
REFUSE_TOL = 1e-3  # and refused above this (the channels' converter masks above it too)


def _arrays(kind: str, msgs: list, geo):
    """(position (m, 3), quaternion (m, 4) or None, covariance (m, 3, 3) or None, usable (m,))."""
    if kind == "navsatfix":
        lat, lon, alt = (np.array([getattr(m, k) for m in msgs], float) for k in ("latitude", "longitude", "altitude"))
        status = np.array([m.status.status if hasattr(m, "status") else 0 for m in msgs], float)
        ok = (status >= 0) & np.isfinite(lat) & np.isfinite(lon) & np.isfinite(alt)
        ok &= (np.abs(lat) <= 90) & (np.abs(lon) <= 180) & ~((lat == 0) & (lon == 0))
        pos = geo.forward(lat, lon, alt, ok)
        known = np.array([getattr(m, "position_covariance_type", 1) != 0 for m in msgs])
        cov = np.array([tuple(m.position_covariance) for m in msgs], float).reshape(-1, 3, 3)
        cov[~known] = 0.0
        return pos, None, cov, ok
    poses = [m.pose.pose for m in msgs] if kind == "odometry" else [rosmsg._pose_of(m) for m in msgs]
    pos = np.array([(p.position.x, p.position.y, p.position.z) for p in poses], float).reshape(-1, 3)
    quat = np.array(
        [(p.orientation.x, p.orientation.y, p.orientation.z, p.orientation.w) for p in poses], float
    ).reshape(-1, 4)
    cov = None
    if kind == "odometry" or hasattr(msgs[0].pose, "covariance"):
        cov = np.array([tuple(m.pose.covariance) for m in msgs], float).reshape(-1, 6, 6)[:, :3, :3].copy()
    return pos, quat, cov, np.ones(len(pos), bool)


def _check_kind(rec: Recording, topic, where: str) -> None:
    if rosmsg.kind_of(topic.type) not in ESTIMATE_KINDS:
        raise DataError(
            rec.path,
            f"{where} is a {topic.type}, which is not a trajectory (an estimate is an "
            "Odometry, PoseStamped, PoseWithCovarianceStamped, a TF pair, a Path or a "
            "NavSatFix)",
        )


def _orientation(rec: Recording, e, where: str, quat, ok, report: Report):
    """Unit quaternions where ``ok`` (NaN elsewhere; ``ok`` narrowed in place), or None if none recorded."""
    if quat is None or np.all(quat == 0):
        return None
    ok &= np.isfinite(quat).all(axis=1)
    norm = np.linalg.norm(quat, axis=1)
    off = np.abs(norm - 1.0)
    bad = np.flatnonzero(ok & (off > REFUSE_TOL))
    if len(bad):
        raise DataError(
            rec.path,
            f"{where}: non-unit quaternion at message {int(bad[0])} (norm "
            f"{norm[bad[0]]:.6g}; a recorded orientation must be a unit quaternion)",
        )
    fix = ok & (off > REPAIR_TOL)
    if fix.any():
        report.add(
            "repaired",
            e.name,
            int(fix.sum()),
            f"{e.topic}: quaternion norm off by more than {REPAIR_TOL:g} (at most {REFUSE_TOL:g}): normalised",
        )
    return np.where(ok[:, None], quat / np.where(norm > 0, norm, 1.0)[:, None], np.nan)


def _drop(rec: Recording, e, where: str, ok, report: Report) -> None:
    if (~ok).any():
        report.add(
            "dropped",
            e.name,
            int((~ok).sum()),
            f"{e.topic}: poses with no usable value (non-finite position or quaternion, NavSatFix without a fix)",
        )
    if not ok.any():
        raise DataError(rec.path, f"{where}: no usable pose ({len(ok)} message(s), every one dropped)")


def _covariance(e, cov, ok, report: Report):
    """``cov`` with unknown ones (all zero or not finite) NaN, or None if every kept one is unknown."""
    if cov is None:
        return None
    unknown = ~np.isfinite(cov).all(axis=(1, 2)) | np.all(cov == 0, axis=(1, 2))
    cov[unknown] = np.nan
    if unknown[ok].all():
        return None
    if unknown[ok].any():
        report.add(
            "masked",
            f"{e.name}_covariance",
            int(unknown[ok].sum()),
            f"{e.topic}: covariance unknown (all zero or not finite): no NEES at those poses",
        )
    return cov


def _check_overlap(rec: Recording, e, where: str, st, ok, ref_span: tuple[int, int] | None) -> None:
    offset_ns = int(round(e.params.get("t_offset", 0.0) * 1e9))
    s = st[ok] + offset_ns
    if ref_span is not None and (s[-1] < ref_span[0] or s[0] > ref_span[1]):
        raise DataError(
            rec.path,
            f"{where}: its stamps ({s[0] / 1e9:.3f} .. {s[-1] / 1e9:.3f} s"
            + (f" with t_offset {e.params['t_offset']:g} s" if offset_ns else "")
            + f") do not overlap the reference's ({ref_span[0] / 1e9:.3f} .. "
            f"{ref_span[1] / 1e9:.3f} s): nothing to score",
        )


def _frames(e, topic, msgs: list, kind: str) -> tuple[str, str]:
    """(frame, child) of the estimate's poses."""
    frame = str(getattr(msgs[0].header, "frame_id", "") or "")
    if not frame and rosmsg.kind_of(topic.type) == "path":  # poses without a frame: the Path's
        frame = str(topic.msgs[-1].header.frame_id)
    child = e.child or (str(msgs[0].child_frame_id) if kind == "odometry" else "")
    if kind == "navsatfix":
        frame = "ENU local"
    return rosmsg.frame_name(frame), rosmsg.frame_name(child)


def _report_estimate(report: Report, e, topic, ok, quat, cov) -> None:
    has = [w for w, v in (("orientation", quat), ("position covariance", cov)) if v is not None]
    report.add(
        "info",
        e.name,
        int(ok.sum()),
        f"{e.topic}{e.pair} ({topic.type}): a recorded estimate of "
        f"{int(ok.sum())} poses at their own stamps"
        + (f", with {' and '.join(has)}" if has else "")
        + "; scored, never a filter input",
    )


def build(
    rec: Recording, mp: Mapping, time: str, geo, t0: int, report: Report, ref_span: tuple[int, int] | None
) -> dict[str, RecordedEstimate]:
    """Every ``[estimates]`` entry of ``mp`` as a RecordedEstimate (module docstring)."""
    out = {}
    for e in mp.estimates:
        topic = rec.topics[e.topic]
        where = f"estimate {e.name} (topic {e.topic}{e.pair})"
        _check_kind(rec, topic, where)
        msgs, logs, kind = sources.messages(rec, e)
        st, _ = sources.stamps(rec, e, msgs, logs, time)
        pos, quat, cov, ok = _arrays(kind, msgs, geo)
        ok &= np.isfinite(pos).all(axis=1)
        quat = _orientation(rec, e, where, quat, ok, report)
        _drop(rec, e, where, ok, report)
        cov = _covariance(e, cov, ok, report)
        _check_overlap(rec, e, where, st, ok, ref_span)
        frame, child = _frames(e, topic, msgs, kind)
        pick = lambda a: None if a is None else a[ok]
        desc = f"{e.topic}{e.pair} ({topic.type})"
        out[e.name] = RecordedEstimate(
            (st[ok] - t0) / 1e9, pos[ok], pick(quat), pick(cov), frame, child, desc, dict(e.params)
        )
        _report_estimate(report, e, topic, ok, quat, cov)
    return out


def meta(estimates: dict[str, RecordedEstimate]) -> dict:
    """What the manifest records of the recorded estimates."""
    return {
        k: {
            "source": e.description,
            "frame": e.frame,
            "child": e.child,
            "poses": len(e),
            "orientation": e.orientation is not None,
            "covariance": e.covariance is not None,
            "params": e.params,
        }
        for k, e in estimates.items()
    }
