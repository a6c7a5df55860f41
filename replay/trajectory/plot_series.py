"""evo_traj's ``--plot`` time series for :mod:`replay.trajectory.plot`: x, y, z (m) and roll, pitch,
yaw (deg) over time, the reference (whole, dashed grey) and each estimate after its alignment (its
matched poses, at the reference's stamps). Angles: roll about x, pitch about y, yaw about z, applied
z-y-x (evo's ``sxyz`` Euler angles), in (-180, 180] deg.
"""

from __future__ import annotations

import numpy as np
from replay.trajectory import quat


AXES = ("x", "y", "z")
ANGLES = ("roll", "pitch", "yaw")


REFERENCE = "0.3"  # the reference's colour (every trajectory figure)


def first_stamp(scores) -> float:
    """The first matched reference stamp over the estimates (time axes start there)."""
    return min(s.reference.t[0] for s in scores.values())


def euler_deg(q) -> np.ndarray:
    """(n, 3) roll, pitch, yaw in degrees of unit quaternions ``q`` (n, 4: x y z w)."""
    R = quat.to_matrix(np.asarray(q, float))
    roll = np.arctan2(R[:, 2, 1], R[:, 2, 2])
    pitch = -np.arcsin(np.clip(R[:, 2, 0], -1.0, 1.0))
    yaw = np.arctan2(R[:, 1, 0], R[:, 0, 0])
    return np.degrees(np.column_stack([roll, pitch, yaw]))


def _panels(reference, scores: dict, ref_values, values_of, names, unit: str, title: str):
    # lazy: start-up, `replay score` imports this module and plots only on request: matplotlib measured ~1.1 s
    from matplotlib.figure import Figure  # noqa: PLC0415

    fig = Figure(figsize=(11.0, 7.5), layout="constrained")
    axes = fig.subplots(3, 1, sharex=True)
    t0 = first_stamp(scores)
    for k, ax in enumerate(axes):
        ax.plot(
            reference.t - t0,
            ref_values[:, k],
            color=REFERENCE,
            ls="--",
            lw=1.1,
            label=f"reference ({reference.name})",
            gid="reference",
        )
        for c, (name, s) in enumerate(scores.items()):
            v = values_of(s)
            if v is not None:
                ax.plot(s.reference.t - t0, v[:, k], lw=0.9, color=f"C{c}", label=name, gid=name)
        ax.set_ylabel(f"{names[k]} ({unit})")
        ax.grid(alpha=0.3)
    axes[0].set_title(title)
    axes[0].legend(fontsize="small")
    axes[-1].set_xlabel("time since the first matched pose (s)")
    return fig


def xyz(reference, scores: dict):
    """x, y, z over time (m), three panels."""
    return _panels(
        reference,
        scores,
        reference.p,
        lambda s: s.aligned.p,
        AXES,
        "m",
        "position over time (estimates aligned as scored)",
    )


def rpy(reference, scores: dict):
    """Roll, pitch, yaw over time (deg), three panels (estimates without orientations left out)."""
    return _panels(
        reference,
        scores,
        euler_deg(reference.q),
        lambda s: None if s.aligned.q is None else euler_deg(s.aligned.q),
        ANGLES,
        "deg",
        "orientation over time, z-y-x Euler angles (estimates aligned as scored)",
    )
