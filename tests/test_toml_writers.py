"""The TOML files replay writes (a proposed mapping, tune's tuned.toml) are written by tomli-w and read
back to what was written: round trips through the loaders that read them."""
import tomllib
from types import SimpleNamespace

from replay.adapters.mapping import Entry, Mapping, from_dict
from replay.campaign import spec
from replay.tune.write import _toml


def test_a_mapping_reads_back_to_itself():
    mp = Mapping(
        entries=[
            Entry("dvl", "/dvl/twist", type="geometry_msgs/msg/TwistWithCovarianceStamped",
                  fusion={"fuse": ["velocity"], "noise": {"velocity": 0.02}}),
            Entry("odo", "/odd", type="nav_msgs/msg/Odometry", role="odometry"),
            Entry("tf", "/tf", type="tf2_msgs/msg/TFMessage", frame="map", child="base_link", reference=True),
        ],
        estimates=[Entry("ekf", "/ekf/odom", type="nav_msgs/msg/Odometry", estimate=True,
                         params={"t_max_diff": 0.05, "t_offset": -0.25})],
        time="log", until=12.5, params={"gravity": 9.79}, allow_truncated=True,
    )
    text = mp.to_toml()
    doc = tomllib.loads(text)
    assert doc["time"] == "log" and doc["until"] == 12.5 and doc["params"] == {"gravity": 9.79} and doc["allow_truncated"] is True
    assert doc["channels"]["odo"] == {"topic": "/odd", "type": "nav_msgs/msg/Odometry", "role": "odometry"}
    assert doc["channels"]["dvl"]["noise"] == {"velocity": 0.02} and doc["estimates"]["ekf"]["t_offset"] == -0.25
    back = from_dict(doc)
    got = {e.name: (e.topic, e.type, e.role, e.frame, e.child, e.group, e.params, e.fusion) for e in back.entries + back.estimates}
    want = {e.name: (e.topic, e.type, e.role, e.frame, e.child, e.group, e.params, e.fusion) for e in mp.entries + mp.estimates}
    assert got == want and (back.time, back.until, back.params, back.allow_truncated) == (mp.time, mp.until, mp.params, True)
    assert back.to_toml() == text  # written again: the same text


def test_tuned_toml_reads_back_as_the_campaign_it_describes(tmp_path):
    t = SimpleNamespace(objective="pos_rmse", runs=3, alignment="se3", data_dir=None, task="linear", first=None,
                        split=SimpleNamespace(test=[("sim/linear", {"steps": 60}), ("sim/linear", {})]))
    test = SimpleNamespace(seed=7, task_params={"q": 1.0, "r": None, "lost_threshold": 20.0},
                           filter_params={"q_scale": 0.1 + 0.2, "r_scale": 1e-300, "unset": None})
    rows = [{"filter": "kf", "trials": 8, "tuned_on": "sim/linear", "_test": [test]}]
    text = _toml(t, rows, test.task_params, tmp_path)
    assert text.startswith("# written by replay tune") and "# tuned on sim/linear; objective pos_rmse" in text
    doc = tomllib.loads(text)
    assert doc["campaign"] == {"name": "tuned", "runs": 3, "seed": 7, "alignment": "se3"}
    assert doc["dataset"] == [{"id": "sim/linear", "tasks": ["linear"], "params": {"steps": 60}},
                              {"id": "sim/linear", "tasks": ["linear"]}]
    assert doc["task"] == {"linear": {"q": 1.0, "lost_threshold": 20.0}}  # None: left out (TOML has no null)
    assert doc["filter"] == [{"name": "kf", "params": {"q_scale": 0.30000000000000004, "r_scale": 1e-300}}]
    (tmp_path / "tuned.toml").write_text(text)
    camp = spec.load(tmp_path / "tuned.toml")  # the campaign loader takes it
    assert [c.filter_params for c in camp.configs][:1] == [{"q_scale": 0.30000000000000004, "r_scale": 1e-300}]
