"""Unit quaternions (x, y, z, w): :mod:`replay.util.quat` (a leaf, shared with the bag adapter's
TF composition), re-exported here where the trajectory code has always found them."""

from replay.util.quat import (
    angle,
    conjugate,
    from_matrix,
    from_yaw,
    multiply,
    normalize,
    rotate,  # noqa: F401
    slerp,
    to_matrix,
)
