"""Bad input to ``replay tune``: one line each, exit 2, before any trial (nothing computed)."""
import pytest
from click.testing import CliRunner

from replay.cli import main

BASE = ["sim/linear", "--filters", "kf,pf", "--split", "seeds", "--dataset-param", "steps=20", "--runs", "1",
        "--trials", "2", "-q"]


def refused(tmp_path, *args, base=BASE, match):
    out = tmp_path / "out"
    res = CliRunner().invoke(main, ["tune", *base, *args, "--out", str(out)])
    assert res.exit_code == 2, res.output
    line = res.output.strip()
    assert line.startswith("replay: error: ") and "\n" not in line and "Traceback" not in line, line
    assert match in line, line
    assert not (out / "units").exists() and not (out / "study.db").exists()  # no trial
    return line


@pytest.mark.parametrize("param, match", [
    ("kf.nope=[1.0,2.0]", "filter 'kf' has no parameter 'nope'"),
    ("task.nope=[1.0,2.0]", "has no parameter 'nope'"),
    ("zz.alpha=[0.1,0.2]", "unknown filter 'zz'"),
    ("ukf.alpha=[0.1,0.2]", "filter 'ukf' is not among --filters"),
    ("task.q=[2.0,1.0]", "empty or inverted range"),
    ("task.q=[1.0,1.0]", "empty or inverted range"),
    ("task.q=log[0,1.0]", "a log range needs positive bounds"),
    ("task.q=log[-1,1.0]", "a log range needs positive bounds"),
    ("task.q=[1,3]", "integer range [1, 3] on the float parameter"),
    ("pf.n_particles=[10.5,100.0]", "integer parameter: the range needs integer bounds"),
    ("pf.n_particles=[0,100]", "bound 0"),
    ("pf.resampling=[1,2]", "give choice[...], not a range"),
    ("pf.resampling=choice[systematic,nope]", "resampling must be one of"),
    ("task.q=choice[]", "no choices given"),
    ("task.q=[1.0]", "a range takes two bounds"),
    ("task.q=12", "is not log[a,b], [a,b] or choice"),
    ("kf", "expected FILTER.PARAM=SPEC"),
])
def test_bad_search_space(tmp_path, param, match):
    refused(tmp_path, "-p", param, match=match)


def test_zero_trials_and_bad_objective(tmp_path):
    refused(tmp_path, "-p", "task.q=log[0.1,1]", "--trials", "0", match="--trials 0: at least 1")
    refused(tmp_path, "-p", "task.q=log[0.1,1]", "--objective", "rmse", match="--objective 'rmse'")
    refused(tmp_path, "-p", "task.q=log[0.1,1]", "--objective", "weighted:mean_rmse=0", match="needs a weight > 0")


def test_nll_of_a_particle_filter(tmp_path):
    refused(tmp_path, "-p", "task.q=log[0.1,1]", "--objective", "nll",
            match="filter 'pf' cannot provide the innovations' likelihood")
    refused(tmp_path, "-p", "task.q=log[0.1,1]", "--objective", "weighted:mean_rmse=1,nll=1",
            match="filter 'pf' cannot provide")


def test_nll_of_a_nonlinear_model(tmp_path):
    base = ["sim/ungm", "--filters", "ekf", "--split", "seeds", "--runs", "1", "--trials", "2", "-q"]
    refused(tmp_path, "-p", "task.q=log[0.1,1]", "--objective", "nll", base=base, match="nonlinear model")


def test_overlapping_train_and_test(tmp_path):
    base = ["--filters", "kf", "--dataset-param", "steps=20", "--runs", "1", "--trials", "1", "-q"]
    refused(tmp_path, "--train", "sim/linear", "--test", "sim/linear", "-p", "task.q=log[0.1,1]", base=base,
            match="overlap")
    res = CliRunner().invoke(main, ["tune", *base, "--train", "sim/linear", "--test", "sim/linear", "-p",
                                    "task.q=log[0.1,1]", "--allow-overlap", "--out", str(tmp_path / "o")])
    assert res.exit_code == 0, res.output
    import csv

    rows = list(csv.DictReader(open(tmp_path / "o" / "leaderboard.csv")))
    assert rows and all(r["overlap"].startswith("OVERLAP") for r in rows)
    assert "training and test data overlap" in res.output


def test_split_options(tmp_path):
    refused(tmp_path, "-p", "task.q=log[0.1,1]", "--train-segment", "0.6", match="give exactly one of")
    base = ["sim/linear", "--filters", "kf", "--runs", "1", "--trials", "1", "-q"]
    refused(tmp_path, "-p", "task.q=log[0.1,1]", base=base, match="give exactly one of")
    refused(tmp_path, "-p", "task.q=log[0.1,1]", "--train-segment", "1.5", base=base, match="in (0, 1)")
    refused(tmp_path, "--split", "runs", "-p", "task.q=log[0.1,1]", base=base, match="only split")


def test_no_space(tmp_path):
    refused(tmp_path, match="no search space")


def test_study_of_another_configuration(tmp_path):
    out = tmp_path / "out"
    ok = CliRunner().invoke(main, ["tune", *BASE, "-p", "task.q=log[0.1,1]", "--out", str(out)])
    assert ok.exit_code == 0, ok.output
    res = CliRunner().invoke(main, ["tune", *BASE, "-p", "task.q=log[0.1,2]", "--out", str(out)])
    assert res.exit_code == 2
    assert "belongs to another configuration (differs in: space)" in res.output
    res = CliRunner().invoke(main, ["tune", *BASE, "-p", "task.q=log[0.1,1]", "--objective", "lost", "--out",
                                    str(out)])
    assert res.exit_code == 2 and "differs in: objective" in res.output


def test_space_file(tmp_path):
    f = tmp_path / "space.toml"
    f.write_text('[pf]\nn_particles = [10, 5.5]\n')
    refused(tmp_path, "--space", str(f), match="space.toml: pf.n_particles")
    f.write_text('pf = 3\n')
    refused(tmp_path, "--space", str(f), match="expected FILTER.PARAM = SPEC")
    f.write_text('[pf\n')
    refused(tmp_path, "--space", str(f), match="not valid TOML")


def test_out_that_is_not_a_tune_directory(tmp_path):
    (tmp_path / "out").mkdir()
    (tmp_path / "out" / "precious.txt").write_text("keep")
    res = CliRunner().invoke(main, ["tune", *BASE, "-p", "task.q=log[0.1,1]", "--out", str(tmp_path / "out")])
    assert res.exit_code == 2 and "not a replay tune output" in res.output
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == ["precious.txt"]


def test_task_parameters_of_a_synthetic_task(tmp_path):
    base = ["sim/auv-sonar", "--filters", "ekf", "--split", "seeds", "--runs", "1", "--trials", "1", "-q"]
    refused(tmp_path, "-p", "task.yaw_rate=[0.0,0.5]", base=base, match="draws its measurements from the reference")
