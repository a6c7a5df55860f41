"""Which inputs a task uses (issue 12, items 1, 2, 4, 5): channel roles instead of channel names,
the inputs and notes recorded in the manifest, noise parameters refused unless finite and
positive (definite), a time column in milliseconds converted, and a missing channel explained.
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from hostile import assert_ok
from replay.adapters import bags
from replay.adapters.bohai import load as load_bohai
from replay.adapters.mapping import from_dict, role_of
from replay import evaluate  # the API: keywords in, one EvalOptions record built
from replay.frame import Channel, Frame
from replay.models.noise import Covariance
from replay.roles import as_meta, of_role
from replay.tasks import TASKS, make_task, role_input, task_class, why_missing
from replay.util.errors import ReplayError
from test_hostile_adapters import GOOD_MAP, make_bag

REPO = Path(__file__).resolve().parents[1]
RL60 = REPO / "docs" / "mappings" / "rl_test1_60s.toml"
RENAMED = GOOD_MAP.replace("wheel = ", "husky = ").replace("imu = ", "gyro_a = ")


def manifest_of(out: Path) -> dict:
    return json.loads((out / "manifest.json").read_text())


# ---------------------------------------------------------------- roles (item 1)

def test_renamed_channels_give_the_same_numbers_and_are_listed(tmp_path):
    bag = make_bag(tmp_path / "b")
    rmse = {}
    for name, text in (("plain", GOOD_MAP), ("renamed", RENAMED)):
        (tmp_path / f"{name}.toml").write_text(text)
        assert_ok(["eval", bag, "--mapping", tmp_path / f"{name}.toml", "--task", "gps-odom", "-f", "ekf,ukf",
                   "--out", tmp_path / name])
        m = manifest_of(tmp_path / name)
        rmse[name] = {f: r["pos_rmse"] for f, r in m["results"].items()}
        assert m["dataset"]["task_notes"] == []
    assert rmse["renamed"] == rmse["plain"] and all(np.isfinite(v) for v in rmse["plain"].values())
    inputs = manifest_of(tmp_path / "renamed")["dataset"]["task_inputs"]
    assert inputs["odometry_velocity"].startswith("husky_velocity (/wheel (nav_msgs/msg/Odometry)")
    assert inputs["odometry_rate"].startswith("husky_rate (/wheel")
    assert inputs["imu_gyro"].startswith("gyro_a (/imu (sensor_msgs/msg/Imu)")
    assert inputs["gps"].startswith("gps (/fix (sensor_msgs/msg/NavSatFix)")


def test_no_optional_input_is_noted(tmp_path):
    bag = make_bag(tmp_path / "b")
    (tmp_path / "m.toml").write_text(GOOD_MAP.replace('wheel = "/wheel"', 'wheel = { topic = "/wheel", role = "none" }')
                                     .replace('imu = "/imu"', 'imu = { topic = "/imu", role = "none" }'))
    assert_ok(["eval", bag, "--mapping", tmp_path / "m.toml", "--task", "gps-odom", "-f", "ekf",
               "--out", tmp_path / "o"])
    ds = manifest_of(tmp_path / "o")["dataset"]
    assert sorted(ds["task_inputs"]) == ["gps", "reference"]
    assert ds["task_notes"] == ["task gps-odom: no odometry and no imu input (roles odometry, imu; docs/bags.md): "
                                "the filters use the GPS fixes only"]


@pytest.mark.slow
def test_rl_test1_renamed_mapping_same_leaderboard(shared_dir, tmp_path):
    """The issue's case: test1.bag with odometry and IMU renamed ran on GPS alone (ukf NaN)."""
    rec = shared_dir / "datasets" / "bags" / "derived" / "rl_test1_60s_mcap"
    renamed = tmp_path / "renamed.toml"
    renamed.write_text(RL60.read_text().replace("\nimu = ", "\ngyro_a = ").replace("\nodom = ", "\nwheels = "))
    rows = [evaluate(str(rec), task="gps-odom", filters=["ekf", "ukf"], dataset_params={"mapping": str(m)}).rows
            for m in (RL60, renamed)]
    assert [r["pos_rmse"] for r in rows[0]] == [r["pos_rmse"] for r in rows[1]]
    assert rows[0][0]["pos_rmse"] == pytest.approx(1.5811, abs=1e-4)
    assert rows[0][1]["pos_rmse"] == pytest.approx(1.5622, abs=1e-4)


def test_role_declarations():
    mp = from_dict({"channels": {"dvl": {"topic": "/dvl", "role": "odometry"}, "fix": "/fix"}})
    dvl, fix = mp.entries
    assert role_of(dvl, "geometry_msgs/msg/TwistStamped", "m") == "odometry"
    assert role_of(fix, "sensor_msgs/msg/NavSatFix", "m") == "gps"
    with pytest.raises(ReplayError, match=r"m: \[channels\] dvl: topic /dvl is a sensor_msgs/msg/Imu, which cannot "
                                          r"have role 'odometry' \(it takes Odometry, TwistStamped"):
        role_of(dvl, "sensor_msgs/msg/Imu", "m")
    with pytest.raises(ReplayError, match=r"\[reference\] p: a reference has no role"):
        from_dict({"reference": {"p": {"topic": "/p", "role": "gps"}}})
    assert 'role = "odometry"' in mp.to_toml()


def test_legacy_frames_without_roles_use_the_role_names():
    n = 4
    frame = Frame(np.arange(n, dtype=float), {"gps": Channel(np.zeros((n, 3)), "m"),
                                              "odom_velocity": Channel(np.zeros((n, 3)), "m/s")})
    assert role_input(frame, "gps", "t").channels == {"position": "gps"}
    assert role_input(frame, "odometry", "t") is None  # no channel named odom
    frame.roles = ()
    assert role_input(frame, "gps", "t") is None  # an adapter that declares roles: by role only


def test_bohai_roles_gps_gyro_only_when_it_follows_the_yaw_and_attitude(bohai_dir):
    gps, *_, imu = load_bohai(bohai_dir / "20220822_0_6.csv").roles
    assert (gps.role, gps.channels) == ("gps", {"position": "gps_position"})
    assert (imu.role, imu.channels) == ("imu", {"gyro": "gyro", "attitude": "attitude"})
    assert imu.attitude_enu  # its yaw follows the course over ground (0.11 rad)
    f0 = load_bohai(bohai_dir / "20220822_0_0.csv")  # wz does not follow the yaw rate (correlation -0.03)
    assert f0.meta["gyro_attitude"]["wz_yaw"] < 0.3
    # and its yaw is 1.45 rad off the course: the attitude alone, not marked east-north-up
    imu = of_role(f0.roles, "imu")[0]
    assert imu.channels == {"attitude": "attitude"} and imu.attitude_enu is False


def test_bag_meta_roles(tmp_path):
    bag = make_bag(tmp_path / "b")
    f = bags.load(bag, mapping={"channels": {"g": "/fix", "w": {"topic": "/wheel", "role": "velocity"}}})
    roles = as_meta(f.roles)  # as the manifest records them
    assert roles["gps"][0]["channels"] == {"position": "g"}
    assert roles["velocity"][0] == {"entry": "w", "source": "/wheel (nav_msgs/msg/Odometry)",
                                              "declared": True, "channels": {"velocity": "w_velocity"}}
    assert "odometry" not in roles and "roles" not in f.meta


# ---------------------------------------------------------------- noise parameters (item 2)

@pytest.mark.parametrize("task", sorted(TASKS))
def test_noise_parameters_are_bounded(task):
    """Every variance, standard deviation and covariance a task declares refuses <= 0, inf and NaN."""
    cls = task_class(task)
    for p in cls.PARAMS:
        if isinstance(p, Covariance):
            n = p.dim or 2
            bad = np.eye(n)
            bad[0, 1] = bad[1, 0] = 2.0  # symmetric, not positive definite
            for value in (bad.tolist(), [1.0] * (n - 1) + [-1.0], [float("nan")] * n):
                with pytest.raises(ReplayError, match=rf"task '{task}': {p.name} must be an? .*positive-definite"):
                    make_task(task, **{p.name: value})
        elif p.type is float and (p.name.split("_")[0] in ("q", "r", "p0") or "sigma" in p.name):
            assert p.low == 0 and p.low_open and p.finite, p.name
            for value in (0.0, -2.0, float("inf"), float("nan")):
                with pytest.raises(ReplayError, match=rf"task '{task}': {p.name} must be a finite number > 0"):
                    make_task(task, **{p.name: value})


# ---------------------------------------------------------------- time unit and missing channels (items 4, 5)

def _head(bohai_dir, rows=None) -> pd.DataFrame:
    return pd.read_csv(bohai_dir / "20220822_0_6.csv", nrows=rows)


def test_time_in_milliseconds_converted_same_numbers(bohai_dir, tmp_path):
    table = _head(bohai_dir, 400)
    table.to_csv(tmp_path / "s.csv", index=False)
    table.assign(time=table["time"] * 1000).to_csv(tmp_path / "ms.csv", index=False)
    fs, fms = load_bohai(tmp_path / "s.csv"), load_bohai(tmp_path / "ms.csv")
    assert fms.meta["time_unit"] == {"unit": "milliseconds", "factor": 1e-3,
                                     "median_step_raw": pytest.approx(102.0, abs=1e-6)}
    np.testing.assert_allclose(fms.t, fs.t, atol=1e-9)
    assert [e.count for e in fms.report.find("repaired", "time")] == [400]
    rows = [evaluate(str(tmp_path / n), task="position", filters=["ekf"]).rows[0] for n in ("s.csv", "ms.csv")]
    assert rows[0]["pos_rmse"] == rows[1]["pos_rmse"]


@pytest.mark.slow
def test_time_in_milliseconds_full_log_keeps_jump_masking(bohai_dir, tmp_path):
    """The issue's case: 0_6 with time in ms gave 2.78 m (jumps not masked) instead of 1.44 m."""
    table = _head(bohai_dir)
    table.assign(time=table["time"] * 1000).to_csv(tmp_path / "ms.csv", index=False)
    f = load_bohai(tmp_path / "ms.csv")
    assert f.meta["jumps"]["masked"] == load_bohai(bohai_dir / "20220822_0_6.csv").meta["jumps"]["masked"] == 2114
    row = evaluate(str(tmp_path / "ms.csv"), task="position", filters=["ekf"]).rows[0]
    assert row["pos_rmse"] == pytest.approx(1.4434, abs=1e-4)


def test_infinite_cells_keep_the_column(bohai_dir, tmp_path):
    table = _head(bohai_dir, 400)
    table.loc[100:149, "roll"] = np.inf
    table.to_csv(tmp_path / "inf.csv", index=False)
    f = load_bohai(tmp_path / "inf.csv")
    assert "attitude" in f.channels and int((~f.channels["attitude"].valid).sum()) == 50
    assert [e.count for e in f.report.find("masked", "roll")] == [50]
    assert "roll" not in f.meta["dropped_columns"]


def test_why_missing_names_the_report_line(bohai_dir, tmp_path):
    table = _head(bohai_dir, 400)
    table.assign(wy=0.0).to_csv(tmp_path / "z.csv", index=False)
    f = load_bohai(tmp_path / "z.csv")
    assert "gyro" not in f.channels
    assert why_missing(f, ("gyro",)) == "the adapter dropped wy (400 samples: all zero)"
    assert why_missing(f, ("attitude",)) == ""
