"""The :class:`Trajectory` (stamped poses) and the checks every reader applies (:func:`make`).

A trajectory is ``t`` (n,) seconds, ``p`` (n, 3) positions (m), ``q`` (n, 4) unit
quaternions ``x, y, z, w`` (orientation of the body in the trajectory's frame; None for
position-only sources such as GNSS fixes) and an optional covariance ``cov``: (n, 6, 6)
for a pose (x, y, z, roll, pitch, yaw, the ROS ``PoseWithCovariance`` layout, in the
parent frame) or (n, 3, 3) for a position.

Refused, one line naming the source and the row (file line, or message index):
fewer than :data:`MIN_POSES` poses, a non-finite value, a quaternion whose norm is
not within :data:`QUAT_TOL` of 1 (those within are normalised), a stamp equal to the
previous one (duplicate) or before it (time not increasing).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from replay.util.errors import DataError, shown
from replay.trajectory import quat

MIN_POSES = 3
QUAT_COLUMNS = ("qx", "qy", "qz", "qw")  # of to_pandas / from_pandas
QUAT_TOL = 1e-3  # |‖q‖ - 1| allowed (printed quaternions carry 6-9 digits); larger is an error in the data


@dataclass(frozen=True)
class Trajectory:
    t: np.ndarray
    p: np.ndarray
    q: np.ndarray | None = None
    cov: np.ndarray | None = None
    name: str = ""
    source: str = ""  # file (and topic) it was read from, for messages
    ns: np.ndarray | None = None  # the stamps in integer ns, exactly as read (replay.trajectory.stamps)

    def __len__(self) -> int:
        return len(self.t)

    @property
    def has_orientation(self) -> bool:
        return self.q is not None

    def take(self, idx) -> Trajectory:
        """The poses at ``idx`` (indices or a boolean mask)."""
        return replace(
            self,
            t=self.t[idx],
            p=self.p[idx],
            q=None if self.q is None else self.q[idx],
            cov=None if self.cov is None else self.cov[idx],
            ns=None if self.ns is None else self.ns[idx],
        )

    def to_pandas(self):
        """The poses as a DataFrame: columns ``t`` (s), ``x, y, z`` (m) and, with an orientation,
        ``qx, qy, qz, qw``; ``attrs``: ``name``, ``source`` (the covariance is left out)."""
        # lazy: start-up, pandas measured ~740 ms: the trajectory core stays numpy-only
        import pandas as pd  # noqa: PLC0415

        cols = {"t": self.t, "x": self.p[:, 0], "y": self.p[:, 1], "z": self.p[:, 2]}
        if self.q is not None:
            cols.update(zip(QUAT_COLUMNS, self.q.T))
        df = pd.DataFrame(cols)
        df.attrs.update(name=self.name, source=self.source)
        return df

    @classmethod
    def from_pandas(cls, df, *, name: str = "") -> Trajectory:
        """A checked trajectory (:func:`make`) of a DataFrame with columns ``t, x, y, z`` and
        optionally all of ``qx, qy, qz, qw`` (other columns are ignored); ``name``: default
        ``df.attrs["name"]``. Messages name the DataFrame and the row (0-based position)."""
        name = name or str(df.attrs.get("name") or "DataFrame")
        source = f"DataFrame {name}"
        missing = [c for c in ("t", "x", "y", "z") if c not in df.columns]
        quat = [c for c in QUAT_COLUMNS if c in df.columns]
        if missing or 0 < len(quat) < 4:
            absent = missing or [c for c in QUAT_COLUMNS if c not in quat]
            raise DataError(
                source,
                f"lacks column{'s' if len(absent) > 1 else ''} {', '.join(absent)}: expected t, "
                f"x, y, z (s, m) and optionally all of {', '.join(QUAT_COLUMNS)} "
                f"(columns: {', '.join(map(str, df.columns))[:120]})",
            )
        wanted = ["t", "x", "y", "z", *quat]
        twice = [c for c in wanted if list(df.columns).count(c) > 1]
        if twice:
            raise DataError(source, f"column {shown(twice[0])} appears twice")
        bad = [c for c in wanted if df[c].dtype.kind not in "iuf"]
        if bad:
            raise DataError(
                source,
                f"column {shown(bad[0])} is not numeric (dtype {df[bad[0]].dtype}): t in seconds, positions in metres",
            )
        values = df[wanted].to_numpy(float)
        return make(
            values[:, 0],
            values[:, 1:4],
            values[:, 4:8] if quat else None,
            source=source,
            name=name,
            rows=np.arange(len(values)),
        )

    def transformed(self, R: np.ndarray, t: np.ndarray, c: float = 1.0) -> Trajectory:
        """The trajectory moved by x -> c R x + t (orientations rotated by R, covariance by c R)."""
        R = np.asarray(R, float)
        p = c * self.p @ R.T + t
        q = None if self.q is None else quat.multiply(quat.from_matrix(R), self.q)
        cov = self.cov
        if cov is not None:
            k = cov.shape[-1]
            J = np.eye(k)
            J[:3, :3] = c * R
            if k == 6:
                J[3:, 3:] = R  # small-angle attitude errors in the parent frame rotate with it
            cov = J @ cov @ J.T
        return replace(self, p=p, q=q, cov=cov)


def _where(rows, i: int, unit: str) -> str:
    return f"{unit} {int(rows[i]) if rows is not None else i + 1}"


def make(
    t,
    p,
    q=None,
    cov=None,
    *,
    source,
    name: str = "",
    rows=None,
    unit: str = "row",
    min_poses: int = MIN_POSES,
    ns=None,
) -> Trajectory:
    """A checked :class:`Trajectory` (module docstring). ``rows`` gives each pose's line number
    (or message index) for the messages; ``unit`` names it ("row", "message"); ``ns``: the stamps in
    integer nanoseconds as read (:mod:`replay.trajectory.stamps`), kept when there is one per pose."""
    t = np.asarray(t, float).reshape(-1)
    p = np.asarray(p, float).reshape(-1, 3)
    n = len(t)
    if n < min_poses:
        raise DataError(source, f"{n} pose{'s' if n != 1 else ''}: a trajectory needs at least {min_poses}")
    if len(p) != n:
        raise DataError(source, f"{len(p)} positions for {n} stamps")

    def bad(mask, what):
        i = int(np.flatnonzero(mask)[0])
        where = _where(rows, i, unit)
        if unit == "row":
            raise DataError(source, what(i), row=int(rows[i]) if rows is not None else i + 1)
        raise DataError(source, f"{where}: {what(i)}")

    if not np.isfinite(t).all():
        bad(~np.isfinite(t), lambda i: f"stamp {t[i]} is not a finite number")
    if not np.isfinite(p).all():
        bad(~np.isfinite(p).all(axis=1), lambda i: f"position {p[i].tolist()} is not finite")
    if q is not None:
        q = np.asarray(q, float).reshape(-1, 4)
        norm = np.linalg.norm(q, axis=1)
        off = ~(np.abs(norm - 1.0) <= QUAT_TOL)
        if off.any():
            bad(
                off,
                lambda i: (
                    f"quaternion (x, y, z, w) = {np.round(q[i], 6).tolist()} has norm {norm[i]:.6g}, "
                    f"not 1 (tolerance {QUAT_TOL:g}): not a rotation"
                ),
            )
        q = q / norm[:, None]
    dt = np.diff(t)
    if (dt == 0).any():
        bad(np.concatenate([[False], dt == 0]), lambda i: f"duplicate stamp {t[i]:.9f} s (as the previous pose)")
    if (dt < 0).any():
        bad(
            np.concatenate([[False], dt < 0]),
            lambda i: f"time goes backwards: stamp {t[i]:.9f} s is before the previous {t[i - 1]:.9f} s",
        )
    if cov is not None:
        cov = np.asarray(cov, float)
        if cov.shape not in ((n, 6, 6), (n, 3, 3)):
            raise DataError(source, f"covariance of shape {cov.shape}: expected ({n}, 6, 6) or ({n}, 3, 3)")
    ns = None if ns is None or len(ns) != n else np.asarray(ns, np.int64)
    return Trajectory(t, p, q, cov, name=name or str(source), source=str(source), ns=ns)
