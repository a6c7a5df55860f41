"""Paper 001 reproduction: the water-track DVL of the simulator, the unobservable drift, the document."""
import numpy as np
import pytest

from replay.evaluate import evaluate
from replay.sim.sauv_current import make_frame

NOISE_FREE = {"dvl_percent": 0.0, "ahrs_sigma_deg": 0.0, "acc_bias": 0.0, "acc_noise_density": 0.0}


def test_water_track_measures_through_water_velocity():
    bottom = make_frame(np.random.default_rng(3), **NOISE_FREE)
    water = make_frame(np.random.default_rng(3), dvl_track="water", **NOISE_FREE)
    v_ground = bottom.reference["velocity_body"].values
    assert np.allclose(bottom.channels["dvl_velocity"].values, v_ground)
    dvl = water.channels["dvl_velocity"].values
    assert np.abs(dvl[:, 1:]).max() < 1e-9  # through the water the AUV only surges (no roll, no slip)
    assert np.abs(dvl[:, 0] - v_ground[:, 0]).max() > 0.1  # ... and the current is not in it
    # the truth and every other channel are the same; bottom lock is the default, draws unchanged
    assert np.array_equal(water.reference["position"].values, bottom.reference["position"].values)
    assert np.array_equal(water.channels["accel"].values, bottom.channels["accel"].values)
    default = make_frame(np.random.default_rng(3))
    explicit = make_frame(np.random.default_rng(3), dvl_track="bottom")
    assert np.array_equal(default.channels["dvl_velocity"].values, explicit.channels["dvl_velocity"].values)
    assert water.meta["dvl_track"] == "water"


def test_water_track_error_is_the_integrated_current():
    """With noise-free sensors in water track the UKF's final horizontal error is the current's
    displacement over the mission (north/east are unobservable): within the prior's few metres."""
    params = dict(NOISE_FREE, dvl_track="water", strength=0.5)
    ev = evaluate("sim/sauv-current", filters=("ukf",), runs=2, seed=0, dataset_params=params)
    for run in range(2):
        from replay.pipeline import load_frame

        frame = load_frame(ev.results[0].config, run)
        cur = frame.reference["current"].values
        T = frame.meta["dt"]
        shift = np.linalg.norm(T * cur[:-1].sum(axis=0))
        final = ev.results[0].runs[run]["final_err"]
        assert shift > 50
        assert final == pytest.approx(shift, abs=6.0)
    bottom = evaluate("sim/sauv-current", filters=("ukf",), runs=2, seed=0,
                      dataset_params=dict(NOISE_FREE, strength=0.5))
    assert bottom.rows[0]["pos_rmse"] < 0.1 * ev.rows[0]["pos_rmse"]


@pytest.mark.slow
def test_reproduce_001_quick(tmp_path):
    from replay.reproduce.p001 import run
    from replay.reproduce.verdict import check_portable

    doc = tmp_path / "001.md"
    evs = run(quick=True, runs=2, doc=doc, quiet=True)
    text = doc.read_text(encoding="utf-8")
    assert text.startswith("# Reproduction of paper 001")
    head = text.split("## Setting")[0]
    assert "## Verdict" in head and "(of 6 claims)" in head
    for section in ("## North and east are unobservable", "## Bottom-lock DVL", "## Water-track DVL",
                    "## Forgetting factor b", "## Ablation", "## What this implies"):
        assert section in text
    assert "adapt_means=none" in text and "dvl_track=water" in text and "aukf.forgetting=0.95" in text
    check_portable(text, "001.md")
    assert (tmp_path / "001_traces.png").exists()
    # the numbers behind the verdicts
    floor_w = evs["water noise-free"].rows[0]["pos_rmse"]
    floor_b = evs["bottom noise-free"].rows[0]["pos_rmse"]
    assert floor_w > 40 and floor_b < 6
    main = evs["bottom 0.5"].rows
    assert main[1]["pos_rmse"] > 3 * main[0]["pos_rmse"]  # the paper's AUKF loses in bottom lock
