"""`replay datasets info` takes whatever `replay eval` takes (issue 23, item 13): a registered id, a
CSV path, a ROS 1 .bag, a ROS 2 bag directory, an .mcap (with --mapping), with --adapter and
--dataset-param; the frame is read by eval's own reader (``replay.run.pipeline.load_frame``)."""
from pathlib import Path

import pytest
from hostile import assert_ok, assert_refused, register

from replay.run.pipeline import load_frame

MAPPINGS = Path(__file__).resolve().parents[1] / "docs" / "mappings"


def frame_of(dataset, mapping=None, adapter=None):
    params = {"mapping": str(mapping)} if mapping else {}
    return load_frame({"dataset": str(dataset), "dataset_params": params, "first": None, "seed": 0,
                       "adapter": adapter}, 0)


@pytest.mark.parametrize("rel, mapping, samples", [
    ("bohai/20220822_0_0.csv", None, 3478),
    # test1.bag whole (5-10 s) is slow: the fast subset keeps its 60 s SQLite and MCAP conversions
    pytest.param("bags/robot_localization/test1.bag", None, 16806, marks=pytest.mark.slow),
    ("bags/derived/rl_test1_60s_sqlite3", None, 2551),
    ("bags/derived/rl_test1_60s_mcap", "rl_test1_60s.toml", 2551),
    ("bags/evo/nav2_turtlebot.mcap", None, 2769),
])
def test_info_reads_what_eval_reads(rel, mapping, samples, shared_dir):
    path = shared_dir / "datasets" / rel
    args = ["datasets", "info", path] + (["--mapping", MAPPINGS / mapping] if mapping else [])
    out = assert_ok(args).stdout.splitlines()
    assert out[0] == f"{'path:':15s} {path}" and out[1] == "summary:"
    frame = frame_of(path, MAPPINGS / mapping if mapping else None)
    assert len(frame) == samples
    assert out[2:2 + len(frame.summary())] == [f"  {line}" for line in frame.summary()]
    assert ("report:" in out) or any(line.startswith("report: nothing") for line in out)


def test_info_of_a_lake_log_with_adapter_and_a_sim_with_a_parameter(tmp_path):
    log = tmp_path / "lake.csv"
    assert_ok(["datasets", "make", "sim/lake-depth", "--out", log])
    out = assert_ok(["datasets", "info", log, "--adapter", "lake"]).stdout
    assert f"  samples {len(frame_of(log, adapter='lake'))}," in out
    out = assert_ok(["datasets", "info", "sim/ungm", "--dataset-param", "q=10"]).stdout
    assert "  q: 10.0" in out.splitlines()


INFO_REFUSALS = {
    "info-path-missing": (["nowhere/log.csv"], r"^replay: error: nowhere/log\.csv: no such file$"),
    "info-unknown-extension": (["{tmp}/log.xyz"], r"cannot tell the file format from its extension '\.xyz'"),
    "info-sim-bad-param": (["sim/ungm", "--dataset-param", "q=-1"], r"^replay: error: .*\bq\b"),
    "info-mapping-wrong-topics": (["{bags}/evo/nav2_turtlebot.mcap", "--mapping", str(MAPPINGS / "auv.toml")],
                                  r"topic /dvl/twist \(mapped to dvl\) is not in the recording"),
}
register(*INFO_REFUSALS)


@pytest.mark.parametrize("case", list(INFO_REFUSALS))
def test_info_refusals_are_one_line(case, tmp_path, shared_dir):
    args, match = INFO_REFUSALS[case]
    (tmp_path / "log.xyz").write_text("1\n")
    args = [a.format(tmp=tmp_path, bags=shared_dir / "datasets" / "bags") for a in args]
    assert_refused(["datasets", "info", *args], match, cwd=tmp_path)
