"""``replay.score`` from Python (issue 28, "Scoring from Python"): the same numbers as ``replay score``
(printed, ``-o`` CSV), inputs as paths, Trajectory objects or DataFrames, ``stats()``, ``errors()``,
``leaderboard()``, ``plot()``, ``Trajectory.to_pandas``/``from_pandas``, one-line refusals."""
from __future__ import annotations

import csv
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from click.testing import CliRunner
from scipy.spatial.transform import Rotation

import replay
from replay.cli.main import main
from replay.trajectory import Trajectory, load
from replay.trajectory.base import make
from replay.util.errors import DataError, ReplayError
from replay.util.files import fmt, write_csv
from test_score_cli import files  # noqa: F401 — the fixture

STATS = ("rmse", "mean", "median", "std", "min", "max", "sse")


@pytest.fixture
def here(files, monkeypatch):
    """gt.tum and two noisy, rotated, scaled estimates vo.tum, ekf.tum (test_score_cli), as the working directory."""
    monkeypatch.chdir(files)
    return files


def cli(*args):
    r = CliRunner().invoke(main, ["score", *map(str, args)], catch_exceptions=False)
    assert r.exit_code == 0, r.output
    return r.output


def printed(output: str, estimate: str, metric: str, relation: str) -> dict:
    """The statistics block ``replay score`` prints for one estimate, metric and relation (as text)."""
    from replay.cli.score_steps import REL_TITLES

    part = output.split(f"{estimate} vs ", 1)[1].split(" vs ", 1)[0]
    block = part.split(f"{metric.upper()} w.r.t. {REL_TITLES[relation]}", 1)[1].split("w.r.t.", 1)[0]
    return {ln.split("\t")[0].strip(): ln.split("\t")[1] for ln in block.splitlines() if "\t" in ln}


CASES = [
    (dict(align="se3"), ["-a"]),
    (dict(align="sim3", pose_relation=["trans", "angle_deg"], delta=1.0, delta_unit="m"),
     ["-as", "-r", "trans", "-r", "angle_deg", "-d", "1", "-u", "m"]),
    (dict(align="yaw", pose_relation=["full", "point_distance", "point_distance_error_ratio"], rpe=True,
          all_pairs=True, delta=5, n_to_align=100, t_max_diff=0.005),
     ["--align", "yaw", "-r", "full", "-r", "point_distance", "-r", "point_distance_error_ratio", "--rpe",
      "--all-pairs", "-d", "5", "--n-to-align", "100", "--t-max-diff", "0.005"]),
    (dict(align_origin=True, pose_relation="rot_part", delta=2.0, delta_unit="s", pairs_from_reference=True,
          t_offset=0.001, lost_threshold=3.0), ["--align-origin", "-r", "rot_part", "-d", "2", "-u", "s",
                                                "--pairs-from-reference", "--t-offset", "0.001",
                                                "--lost-threshold", "3"]),
]


@pytest.mark.parametrize("api,flags", CASES, ids=["se3", "sim3-rpe-m", "yaw-all-pairs", "origin-seconds"])
def test_python_equals_the_cli_printed_statistics_and_csv(here, api, flags):
    output = cli("gt.tum", "vo.tum", "ekf.tum", *flags, "-o", "cli.csv")
    r = replay.score("gt.tum", ["vo.tum", "ekf.tum"], **api)
    stats = r.stats()
    rows = {row["filter"]: row for row in csv.DictReader(open("cli.csv"))}
    assert list(stats["estimate"].unique()) == ["vo", "ekf"] and len(stats) == len(rows) * len(
        set(zip(stats["metric"], stats["relation"])))
    for _, row in stats.iterrows():
        block = printed(output, row["estimate"], row["metric"], row["relation"])
        for k in STATS:
            assert f"{row[k]:.6f}" == block[k], (row["estimate"], row["metric"], row["relation"], k)
            assert fmt(row[k]) == rows[f"recorded:{row['estimate']}"][f"{row['metric']}_{row['relation']}_{k}"]
    # the whole leaderboard: the CSV the CLI writes, byte for byte (configuration hashes included)
    write_csv(r.rows, here / "api.csv", list(r.leaderboard().columns))
    assert (here / "api.csv").read_text() == (here / "cli.csv").read_text()
    lb = r.leaderboard()
    assert list(lb.columns) == next(csv.reader(open("cli.csv")))
    assert lb["ape_" + stats["relation"].iloc[0] + "_rmse"].tolist() == stats.loc[
        stats["metric"] == "ape", "rmse"].tolist()[::len(set(stats.loc[stats["metric"] == "ape", "relation"]))]


def test_issue_acceptance_command_prints_the_cli_statistics(here):
    """The issue's line, run as written (a wide terminal so that pandas prints every column)."""
    code = "import replay; r = replay.score('gt.tum', ['vo.tum'], align='se3'); print(r.stats())"
    env = {**os.environ, "COLUMNS": "250"}
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=120)
    assert res.returncode == 0 and res.stderr == "", res.stderr
    head, line = res.stdout.splitlines()
    assert head.split() == ["estimate", "metric", "relation", "unit", "n", *STATS]
    cells = line.split()
    block = printed(cli("gt.tum", "vo.tum", "-a", "-o", "cli.csv"), "vo", "ape", "trans")
    assert cells[1:6] == ["vo", "ape", "trans", "m", "300"]
    assert {k: f"{float(c):.6f}" for k, c in zip(STATS, cells[6:])} == block  # the six decimals the CLI prints
    row = next(csv.DictReader(open("cli.csv")))
    assert [float(c) for c in cells[6:]] == pytest.approx([float(row[f"ape_trans_{k}"]) for k in STATS], rel=5e-6)


def test_one_path_traceback_of_the_issue_is_gone_and_inputs_mix(here):
    one = replay.score("gt.tum", "vo.tum")  # the call the issue reports ending in a traceback
    assert list(one.scores) == ["vo"] and one.stats()["n"].tolist() == [300]
    ref, est = load("gt.tum"), load("vo.tum")
    by_path = replay.score(Path("gt.tum"), ["vo.tum", "vo.tum"], align="se3", rpe=True).stats()
    mixed = replay.score(ref.to_pandas(), [est, est.to_pandas()], align="se3", rpe=True).stats()
    assert list(by_path["estimate"].unique()) == ["vo", "vo#2"]
    assert list(mixed["estimate"].unique()) == ["vo.tum", "vo.tum#2"]  # names of the objects
    cols = ["metric", "relation", "n", *STATS]
    assert np.array_equal(by_path[cols].to_numpy(), mixed[cols].to_numpy())
    named = replay.score(ref, [est], names=["orb"])
    assert list(named.scores) == ["orb"] and named.rows[0]["filter"] == "recorded:orb"
    assert named.rows[0]["dataset"] == "gt.tum"  # the reference's name


def test_known_answer_offset_and_rigid_motion():
    t = np.arange(50.0)
    p = np.column_stack([np.cos(t / 8) * 5, np.sin(t / 8) * 5, 0.2 * t])
    ref = make(t, p, source="ref")
    shifted = pd.DataFrame({"t": t, "x": p[:, 0] + 0.3, "y": p[:, 1] - 0.4, "z": p[:, 2]})
    r = replay.score(ref, shifted)
    assert r.stats()["rmse"].tolist() == pytest.approx([0.5], abs=1e-12)
    R = Rotation.from_euler("z", 1.0).as_matrix()
    moved = make(t, p @ R.T + [10, -3, 2], source="moved")
    s = replay.score(ref, moved, align="se3").stats()
    assert s["rmse"].iloc[0] < 1e-9 and replay.score(ref, moved).stats()["rmse"].iloc[0] > 1.0


def test_errors_per_pose_and_per_pair(here):
    r = replay.score("gt.tum", ["vo.tum", "ekf.tum"], align="se3", pose_relation=["trans", "angle_deg"], delta=1)
    ape, stats = r.errors(), r.stats().set_index(["estimate", "metric", "relation"])
    assert list(ape.columns) == ["estimate", "t", "t_estimate", "trans", "angle_deg", "err_x", "err_y", "err_z"]
    for name, part in ape.groupby("estimate", sort=False):
        s = r[name]
        assert np.array_equal(part["t"], s.reference.t) and np.array_equal(part["t_estimate"], s.estimate.t)
        assert np.sqrt(np.mean(part["trans"] ** 2)) == pytest.approx(stats.loc[(name, "ape", "trans"), "rmse"],
                                                                     rel=1e-12)
        assert np.allclose(np.linalg.norm(part[["err_x", "err_y", "err_z"]], axis=1), part["trans"], atol=1e-12)
        assert np.all(np.abs(part["t"] - part["t_estimate"]) <= 0.01)
    rpe = r.errors("rpe")
    assert list(rpe.columns) == ["estimate", "t_i", "t_j", "trans", "angle_deg", "err_x", "err_y", "err_z"]
    assert (rpe["t_j"] > rpe["t_i"]).all() and len(rpe) == stats.xs("rpe", level="metric")["n"].sum() // 2
    with pytest.raises(ReplayError, match=r"^errors: kind must be 'ape' or 'rpe'"):
        r.errors("nees")
    with pytest.raises(ReplayError, match=r"no RPE was computed"):
        replay.score("gt.tum", "vo.tum").errors("rpe")


def test_errors_rpe_ratio_leaves_pairs_of_zero_distance_as_nan():
    t = np.arange(10.0)
    x = np.array([0, 1, 2, 2, 2, 3, 4, 5, 6, 7], float)  # stands still from 2 to 4
    ref = make(t, np.column_stack([x, 0 * x, 0 * x]), source="ref")
    est = make(t, np.column_stack([1.1 * x, 0 * x, 0 * x]), source="vo")
    r = replay.score(ref, est, pose_relation=["point_distance", "point_distance_error_ratio"], rpe=True)
    e = r.errors("rpe")
    assert len(e) == 9 and e["point_distance_error_ratio"].isna().tolist() == [False] * 2 + [True] * 2 + [False] * 5
    assert e["point_distance_error_ratio"].dropna().to_numpy() == pytest.approx(np.full(7, 10.0))
    assert r.stats().query("relation == 'point_distance_error_ratio'")["n"].tolist() == [7]


def test_plot_draws_the_aligned_tracks(here):
    from matplotlib.figure import Figure

    r = replay.score("gt.tum", ["vo.tum", "ekf.tum"], align="sim3", rpe=True)
    fig = r.plot()
    assert isinstance(fig, Figure) and len(fig.axes) == 3
    lines = fig.axes[0].get_lines()
    assert [ln.get_label() for ln in lines] == ["reference (gt)", "vo", "ekf"]
    assert np.array_equal(lines[2].get_xydata(), r["ekf"].aligned.p[:, :2])
    assert np.array_equal(fig.axes[1].get_lines()[0].get_ydata(), r["vo"].ape["trans"])
    with pytest.raises(ReplayError, match=r"^plot: relation 'angle_deg' was not computed \(pose_relation: trans\)$"):
        r.plot(relation="angle_deg")
    with pytest.raises(ReplayError, match=r"^no estimate named 'x' \(estimates: vo, ekf\)$"):
        r["x"]


def test_to_pandas_from_pandas_round_trip_and_refusals():
    t = np.arange(5.0) + 0.5
    q = Rotation.from_euler("z", t[:, None]).as_quat()
    tr = make(t, np.column_stack([t, 2 * t, -t]), q, source="s", name="tr")
    df = tr.to_pandas()
    assert list(df.columns) == ["t", "x", "y", "z", "qx", "qy", "qz", "qw"] and df.attrs["name"] == "tr"
    back = Trajectory.from_pandas(df)
    assert back.name == "tr" and np.array_equal(back.t, tr.t) and np.array_equal(back.p, tr.p)
    assert np.array_equal(back.q, tr.q)
    flat = make(t, np.column_stack([t, t, t]), source="f").to_pandas()
    assert list(flat.columns) == ["t", "x", "y", "z"] and Trajectory.from_pandas(flat).q is None
    for bad, match in [
        (df.drop(columns=["z"]), r"^DataFrame tr: lacks column z: expected t, x, y, z"),
        (df.drop(columns=["qw"]), r"^DataFrame tr: lacks column qw: "),
        (df.assign(x=["a"] * 5), r"^DataFrame tr: column 'x' is not numeric \(dtype \w+\): "),
        (df.assign(t=[0.5, 1.5, 1.5, 3.5, 4.5]), r"^DataFrame tr, row 2: duplicate stamp 1\.5"),
        (df.assign(y=[0, 1, np.nan, 3, 4]), r"^DataFrame tr, row 2: position .* is not finite"),
        (df.assign(qw=2.0), r"^DataFrame tr, row 0: quaternion .* not a rotation"),
    ]:
        with pytest.raises(DataError, match=match) as err:
            Trajectory.from_pandas(bad)
        assert "\n" not in str(err.value)


def test_bad_calls_are_one_line(here):
    tr = load("gt.tum")
    for kwargs, match in [
        (dict(estimates=[]), r"^estimates must be one item or a non-empty list \(got an empty list\)$"),
        (dict(estimates=["vo.tum", 3]), r"^estimates\[1\] must be a path .* or a Trajectory .* or a DataFrame"),
        (dict(estimates="vo.tum", names=["a", "b"]), r"^names: 2 names for 1 estimate$"),
        (dict(estimates=["vo.tum", "ekf.tum"], names=["a", "a"]), r"^names: 'a' is given twice$"),
        (dict(estimates="vo.tum", pose_relation=["trans", "nope"]), r"^pose_relation\[1\] must be one of trans,"),
        (dict(estimates="vo.tum", pose_relation="point_distance_error_ratio"),
         r"^pose_relation point_distance_error_ratio is an RPE relation: add rpe=True"),
        (dict(estimates="nosuch.tum"), r"^nosuch\.tum: no such file$"),
        (dict(estimates="vo.tum", align="se3", align_origin=True), r"origin alignment and se3 alignment exclude"),
        (dict(estimates="vo.tum", relations=["trans"]),
         r"^replay\.score: unknown option 'relations' \(known: .*, pose_relation, "),
    ]:
        est = kwargs.pop("estimates")
        with pytest.raises(ReplayError, match=match) as err:
            replay.score(tr, est, **kwargs)
        assert "\n" not in str(err.value)


@pytest.mark.slow
def test_bag_topics_as_the_cli(shared_dir):
    """evo's ROS_example.bag, as docs/evo.md scores it: the numbers evo_ape prints (docs/evo.md).
    Slow: reads the whole ROS_example.bag (15-30 s), as the other ROS_example.bag scores in tests/
    (slow); the fast subset keeps the API and the CLI printing the same statistics on TUM files
    (test_issue_acceptance_command_prints_the_cli_statistics)."""
    bag = shared_dir / "datasets" / "bags" / "evo" / "ROS_example.bag"
    r = replay.score(f"{bag}:groundtruth", [f"{bag}:ORB-SLAM", f"{bag}:S-PTAM"], align="se3")
    s = r.stats().set_index("estimate")
    assert s.loc["ORB-SLAM", "n"] == 2550 and s.loc["ORB-SLAM", "rmse"] == pytest.approx(5.509938, abs=5e-7)
    output = cli(f"{bag}:groundtruth", f"{bag}:ORB-SLAM", f"{bag}:S-PTAM", "-a")
    for name in ("ORB-SLAM", "S-PTAM"):
        block = printed(output, name, "ape", "trans")
        assert {k: f"{s.loc[name, k]:.6f}" for k in STATS} == block


NOTEBOOK = Path(__file__).resolve().parents[1] / "examples" / "scoring.ipynb"


def test_scoring_notebook_is_committed_executed_and_clean():
    import json

    from test_notebook import runner

    nb = json.loads(NOTEBOOK.read_text())
    code = [c for c in nb["cells"] if c["cell_type"] == "code"]
    assert [c["execution_count"] for c in code] == list(range(1, len(code) + 1))  # top to bottom, once
    assert all(c["outputs"] for c in code) and all("execution" not in c["metadata"] for c in code)
    assert not [o for c in code for o in c["outputs"] if o["output_type"] == "error" or o.get("name") == "stderr"]
    assert runner().machine_paths(nb) == []
    stats = next(c for c in code if c["source"][0].startswith("r = replay.score("))
    table = "".join(stats["outputs"][0]["data"]["text/plain"])
    assert "ORB-SLAM    ape    trans    m  2550  5.509938" in table  # evo_ape bag ... ORB-SLAM -a (docs/evo.md)


@pytest.mark.slow  # a Jupyter kernel: about 10 s
def test_scoring_notebook_runs_top_to_bottom(shared_dir, tmp_path, monkeypatch):
    pytest.importorskip("nbclient")
    pytest.importorskip("ipykernel")
    from test_notebook import runner

    monkeypatch.setenv("REPLAY_SHARED", str(shared_dir))
    nb = runner().execute(NOTEBOOK, tmp_path / "run.ipynb", timeout=600)
    code = [c for c in nb.cells if c.cell_type == "code"]
    assert not [o for c in code for o in c.outputs if o.output_type == "error"]
    assert "5.509938" in code[1].outputs[0]["data"]["text/plain"]
