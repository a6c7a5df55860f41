"""A missing or wrong-kind path given to an option or argument that must exist: the project's one-line
refusal (``replay: error: --mapping FILE: no such file``, exit status 2), never click's usage text."""
import pytest

from cli_helpers import refused


@pytest.mark.parametrize(
    "args, message",
    [
        (["eval", "sim/auv-sonar", "--runs", "3", "--mapping", "{missing}"], "--mapping {missing}: no such file"),
        (["eval", "sim/auv-sonar", "--mapping", "{dir}"], "--mapping {dir}: is a directory, not a file"),
        (["eval", "sim/auv-sonar", "--tuned", "{missing}"], "--tuned {missing}: no such file"),
        (["eval", "sim/auv-sonar", "--tune", "2", "--tune-space", "{missing}"], "--tune-space {missing}: no such file"),
        (["datasets", "info", "sim/auv-sonar", "--mapping", "{missing}"], "--mapping {missing}: no such file"),
        (["rerun", "{missing}"], "{missing}: no such file"),
        (["rerun", "{dir}"], "{dir}: is a directory, not a file"),
        (["leaderboard", "{missing}"], "{missing}: no such file or directory"),
        (["report", "{missing}"], "{missing}: no such directory"),
        (["report", "{file}"], "{file}: is a file, not a directory"),
    ],
)
def test_a_path_that_must_exist_is_refused_in_one_line(tmp_path, args, message):
    (tmp_path / "f.toml").write_text("")
    names = {"missing": tmp_path / "nonexistent.toml", "dir": tmp_path, "file": tmp_path / "f.toml"}
    line = refused([a.format(**names) for a in args], message.format(**names))
    assert line == f"replay: error: {message.format(**names)}"


def test_eval_tune_reads_the_views_and_faults_as_eval_does(tmp_path, monkeypatch):
    """``replay eval --tune`` builds its data options on eval's one path: ``--fault`` reaches the tune
    (it was dropped before), beside ``--rate`` and ``--dataset-param``."""
    from click.testing import CliRunner

    from replay.cli import eval_tune, main

    seen = {}
    monkeypatch.setattr(eval_tune, "run", lambda dataset, **kw: seen.update(kw, dataset=dataset))
    args = ["eval", "sim/linear", "-f", "kf", "--tune", "2", "--fault", "z:outage:t0=20,d=10", "--rate", "5",
            "--dataset-param", "q=2", "--task-param", "r=3", "-o", str(tmp_path / "t")]
    res = CliRunner().invoke(main, args)
    assert res.exit_code == 0, res.output
    assert seen["dataset"] == "sim/linear" and seen["trials"] == 2
    assert seen["dataset_params"] == {"q": 2, "rate": 5.0, "fault": ["z:outage:t0=20,d=10"]}
    assert seen["task_params"] == {"r": 3}
