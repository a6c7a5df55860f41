"""An attitude angle no fused input measures (issue 34, item 5): said on the table, not ranked silently.

When no input measures an angle absolutely (no IMU orientation, no pose attitude; for the heading,
no absolute position either, whose course would fix it), only its rate is integrated and the
declared model's uncertainty on it grows without bound. The filters then estimate different
things: the Kalman filters propagate f(mean) (the dead-reckoned track), the particle filter
returns the posterior mean E[x | z], the mean of particles spread over the angle, which lies
inside the arc they travel: for a Gaussian angle E[cos psi] = cos(psi_bar) exp(-sigma^2 / 2).
Its distance to a dead-reckoned track is then that shrink, not a filter defect.

**What is measured, and why this one.** The angle's standard deviation at every step as the
EKF propagates it under the declared model (the task's ``q_attitude``, ``q_rate``, the rate
inputs' per-message variances and the prior ``P0``): with no absolute attitude nor position, the
pair (angle, its rate) is a linear system of its own (the angle moves by rate * dt, only the rate is
measured; the position and velocity states never feed back into it), so this 2 x 2 Kalman
recursion over the measurement steps is exactly the EKF's variance of the 2-D heading, at a few
microseconds a step, before any filter runs and the same for every row. In 3-D the Euler-angle
rates couple roll, pitch and yaw; each angle is taken with its own body rate (level), an
approximation there. It is the task's declared model (a filter's own ``q_scale`` / ``r_scale``,
as ``replay tune`` sets them, scale it further), not a filter's number: a particle filter's spread
of an angle saturates near the circle's (pi / sqrt 3 = 1.81 rad) and cannot say how far past it
the model's is.

**The threshold.** :data:`SHRINK_LIMIT`: the note is given when the mean over the angle at the end
is pulled inside the arc by more than 1 % (exp(-sigma^2 / 2) < 0.99, sigma > 0.142 rad), the
tolerance of the identity "one odometry fused alone gives its track back" (1 % of the path).
"""

from __future__ import annotations

import math

import numpy as np

SHRINK_LIMIT = 0.01  # the note when the arc's mean is shrunk by more than this share at the end
# (angle, its state index, its rate's state index) per state dimension (replay.models.kinematic)
ANGLES = {2: (("heading (yaw)", 2, 5),), 3: (("roll", 3, 9), ("pitch", 4, 10), ("heading (yaw)", 5, 11))}
POSITION = (0, 1)  # an absolute horizontal position fixes the heading (the course between fixes)
HEADING = "heading (yaw)"


def angle_sd(model, Z, P0, angle: int, rate: int) -> np.ndarray:
    """The declared model's standard deviation of state ``angle`` at every step, as the EKF
    propagates it when only ``rate`` is measured (module docstring), after each step's update."""
    dt = np.maximum(np.asarray(model.dt, float), 1e-9)  # as Kinematic.process_cov
    qa, qr = float(model.q[angle]), float(model.q[rate])
    cols = np.flatnonzero(np.asarray(model.index) == rate)
    Rr = np.where(np.isfinite(Z[:, cols]), model.R_steps[:, cols], np.nan).tolist()
    a, b, c = float(P0[angle, angle]), float(P0[angle, rate]), float(P0[rate, rate])
    out = np.empty(len(dt))
    for k, h in enumerate(dt.tolist()):
        a, b, c = a + 2 * h * b + h * h * c + qa * h, b + h * c, c + qr * h
        for r in Rr[k]:
            if r == r:  # a rate measured at this step
                s = c + r
                a, b, c = a - b * b / s, b * r / s, c * r / s
        out[k] = math.sqrt(max(a, 0.0))
    return out


def unconstrained_angles(model, Z, P0, dims: int, used: dict) -> list[str]:
    """One line per attitude angle no input measures absolutely and whose declared sd at the end
    exceeds the :data:`SHRINK_LIMIT` shrink (naming the angle, its sd and the factor); [] otherwise.
    ``used``: the task's inputs (``Problem.inputs``), named in the line."""
    inputs = [k + " (differential)" * str(v).endswith("(differential)") for k, v in used.items() if k != "reference"]
    seen = {int(i) for i in model.index}
    lines = []
    for name, angle, rate in ANGLES[dims]:
        if angle in seen or (name == HEADING and seen & set(POSITION)):
            continue
        sd = float(angle_sd(model, Z, P0, angle, rate)[-1])
        factor = math.exp(-(sd**2) / 2)
        if 1.0 - factor <= SHRINK_LIMIT:
            continue
        lines.append(
            f"{name} unconstrained: no fused input measures it absolutely (inputs: {', '.join(inputs)}); "
            f"the declared model's sd of it reaches {sd:.2f} rad at the end (EKF-propagated: its rate's "
            f"noise and q_attitude): a posterior-mean estimator (pf) lies inside the arc by "
            f"exp(-sd^2/2) = {factor:.3g}, so its distance to a dead-reckoned track is no filter defect; "
            "the Kalman rows give f(mean)"
        )
    return lines
