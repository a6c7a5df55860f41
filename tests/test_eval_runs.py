"""Issue 27 item 7: units of velocity and acceleration errors; campaign_results(runs=True) on an eval output."""
import json

import numpy as np
import pytest

import replay
from replay.util.errors import ReplayError


@pytest.mark.parametrize("dataset, want", [
    ("sim/uav-formation", {"vx_rmse": "m/s", "vy_rmse": "m/s"}),
    ("sim/sauv-current", {"vx_rmse": "m/s", "vz_rmse": "m/s", "ax_rmse": "m/s^2", "az_rmse": "m/s^2"}),
])
def test_extra_components_carry_the_reference_channels_unit(dataset, want):
    ev = replay.evaluate(dataset, filters=["ukf"], runs=1, first=30)
    assert all(u != "?" for u in ev.units.values()), ev.units
    assert want.items() <= ev.units.items()


def test_campaign_results_runs_of_an_eval_output(tmp_path):
    from replay.outputs.files import write_all

    ev = replay.evaluate("sim/uav-formation", filters=["ekf", "pf"], runs=3, first=40,
                         filter_params={"pf": {"n_particles": 200}})
    write_all(ev, tmp_path / "ev")
    df = replay.campaign_results(tmp_path / "ev", runs=True)
    assert len(df) == 6 and list(df["run"]) == [0, 1, 2] * 2 and set(df["status"]) == {"done"}
    man = json.loads((tmp_path / "ev" / "manifest.json").read_text())
    for name, res in zip(("ekf", "pf"), ev.results):
        g = df[df["filter"] == name]
        assert g["pos_rmse"].tolist() == [m["pos_rmse"] for m in res.runs]  # bit for bit
        assert g["pos_rmse"].mean() == pytest.approx(man["results"][name]["pos_rmse"], rel=1e-15)
        assert np.array_equal(g["vx_rmse"], [m["vx_rmse"] for m in res.runs])
        assert g["params"].iloc[0] == res.params and g["config_hash"].iloc[0] == res.config_hash
    (tmp_path / "ev" / "runs.csv").unlink()
    with pytest.raises(ReplayError, match=r"no units/ and no runs\.csv: a replay eval output written before"):
        replay.campaign_results(tmp_path / "ev", runs=True)
