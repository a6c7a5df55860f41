"""With an alignment, ``replay score``'s leaderboard cells describe the aligned track (issue 28, item 7):
the covariance rotated with it for the NEES, ``lost`` of the aligned error, the numbers before the fit
named ``*_unaligned``. A constructed case with a known answer."""
import numpy as np
import pytest

import replay
from replay.trajectory.base import Trajectory

N = 200


def _case():
    t = np.arange(N) * 0.1
    ang = 2 * np.pi * np.arange(N) / N
    ref = np.c_[20 * np.cos(ang), 20 * np.sin(ang), np.zeros(N)]
    e = np.zeros((N, 3))
    e[:, 0] = 0.1 * (-1.0) ** np.arange(N)  # +-0.1 m along the reference's x: mean zero
    yaw = np.pi / 2  # the estimate's frame: the reference's turned by 90 deg and moved
    R = np.array([[np.cos(yaw), -np.sin(yaw), 0], [np.sin(yaw), np.cos(yaw), 0], [0, 0, 1]])
    off = np.array([100.0, -50.0, 3.0])
    est = (ref + e - off) @ R  # R^T (ref + e - off): the reference frame's point in the estimate's frame
    # tight along the estimate's x (= the reference's y), loose along its y (= the reference's x, the error's axis)
    cov = np.tile(np.diag([1e-2, 1e4, 1e4]), (N, 1, 1))
    return Trajectory(t, ref, name="gt"), Trajectory(t, est, cov=cov, name="est"), e


def test_aligned_cells_and_unaligned_named():
    ref, est, e = _case()
    row = replay.score(ref, est, align="se3", lost_threshold=50.0, lost_steps=5).leaderboard().iloc[0]
    # the aligned error is the +-0.1 m pattern (the fit takes out the frame, not the zero-mean error)
    assert row["pos_rmse"] == pytest.approx(0.1, rel=1e-3) and row["ate"] == pytest.approx(row["pos_rmse"], rel=1e-12)
    assert row["x_rmse"] == pytest.approx(0.1, rel=1e-3) and row["y_rmse"] < 1e-3
    # the covariance turned with the track: the error lies along the loose axis -> NEES about 0.01 / 1e4
    assert row["nees"] == pytest.approx(1e-6, rel=1e-2)
    assert row["lost"] == 0
    # before the fit: the frames differ by 90 deg and ~112 m: far off, lost
    raw = np.linalg.norm(est.p - ref.p, axis=1)
    assert row["pos_rmse_unaligned"] == pytest.approx(np.sqrt(np.mean(raw**2)), rel=1e-12)
    assert row["lost_unaligned"] == 1 and row["nees_unaligned"] > 1.0


def test_no_alignment_no_unaligned_columns():
    ref, est, _ = _case()
    row = replay.score(ref, est).leaderboard().iloc[0]
    assert "pos_rmse_unaligned" not in row.index
    raw = np.linalg.norm(est.p - ref.p, axis=1)
    assert row["pos_rmse"] == pytest.approx(np.sqrt(np.mean(raw**2)), rel=1e-12)
