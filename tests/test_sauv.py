"""Paper 001 simulator: current field, mission, channels, task wiring."""
import numpy as np
import pytest

from replay.sim.sauv_current import current_velocity, make_frame, stream_function


def test_current_field_is_divergence_free():
    x, y = np.meshgrid(np.linspace(-3, 3, 41), np.linspace(-3, 3, 41))
    h = 1e-5
    for t in (0.0, 3.7, 12.0):
        dUe_dx = (current_velocity(x + h, y, t)[0] - current_velocity(x - h, y, t)[0]) / (2 * h)
        dUn_dy = (current_velocity(x, y + h, t)[1] - current_velocity(x, y - h, t)[1]) / (2 * h)
        assert np.max(np.abs(dUe_dx + dUn_dy)) < 1e-6
        # and the velocities are the stream function's derivatives (eq. 112-113)
        dpsi_dx = (stream_function(x + h, y, t) - stream_function(x - h, y, t)) / (2 * h)
        dpsi_dy = (stream_function(x, y + h, t) - stream_function(x, y - h, t)) / (2 * h)
        ue, un = current_velocity(x, y, t)
        assert np.allclose(un, dpsi_dx, atol=1e-8) and np.allclose(ue, -dpsi_dy, atol=1e-8)


def test_frame_mission_and_channels():
    fr = make_frame(np.random.default_rng(0), strength=0.0, ahrs_sigma_deg=0.0)
    assert set(fr.channels) == {"depth", "dvl_velocity", "accel", "attitude"}
    pos = fr.reference["position"].values
    assert pos[:, 2].min() == pytest.approx(-30.0, abs=0.6)  # dives to 30 m (ENU up = -depth)
    assert abs(pos[-1, 2]) < 1e-9 and abs(pos[0, 2]) < 1e-9  # surface at A and G
    v = fr.reference["velocity_body"].values
    assert v[:, 0].max() == pytest.approx(4 * 1852 / 3600, rel=0.01)  # 4 knots
    assert abs(v[-1, 0]) < 0.06  # at rest at G
    # no current: body velocity has no lateral/vertical part
    assert np.abs(v[:, 1:]).max() < 1e-9
    # same seed -> same frame; different seed -> different sensors
    a = make_frame(np.random.default_rng(5)).channels["dvl_velocity"].values
    b = make_frame(np.random.default_rng(5)).channels["dvl_velocity"].values
    c = make_frame(np.random.default_rng(6)).channels["dvl_velocity"].values
    assert np.array_equal(a, b) and not np.array_equal(a, c)


def test_noise_free_model_follows_truth_without_current():
    """Dead-reckoning model f on the true states reproduces the true positions (no current)."""
    from replay.tasks.dead_reckoning import DeadReckoningTask

    fr = make_frame(np.random.default_rng(1), strength=0.0, ahrs_sigma_deg=0.0)
    pb = DeadReckoningTask().build(fr, np.random.default_rng(2))
    truth = pb.truth_position
    v = fr.reference["velocity_body"].values
    a = fr.reference["accel_body"].values
    head = np.pi / 2 - fr.reference["attitude"].values[:, 2]
    X = np.column_stack([truth, v, a, head])
    pred = np.array([pb.model.f(X[k], k + 1) for k in range(len(X) - 1)])
    err = np.abs(pred[:, :3] - truth[1:]).max(axis=1)
    # exact but for the steps where pitch jumps (instant 20 deg changes) or heading turns
    assert np.quantile(err, 0.9) < 1e-3 and err.max() < 0.3
