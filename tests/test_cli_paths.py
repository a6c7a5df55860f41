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
