"""One pipeline: ``replay eval`` and ``replay campaign run`` give identical leaderboard rows.

For every registered filter, with at least one non-default parameter where it
has any (the roughening case of issue 11 among them), on a dataset its model
fits. The campaign computes the runs in blocks of 2, eval in one block: a
run's numbers must not depend on the runs that share its batch.
"""
import csv
import json
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from replay.cli import main
from builtin_cases import group_id, groups
from replay.filters import FILTERS
from replay.run.pipeline import Config, config_hash, run_block

# dataset, dataset params, first, task, {filter: non-default params}: derived from each built-in filter's
# declared CASE (tests/builtin_cases.py), one group per dataset, task and length
GROUPS = [(dataset, {}, first, task, filters) for dataset, task, first, filters in groups()]
IDS = [group_id(g) for g in groups()]
RUNS, SEED = 3, 5
TIMING = ("us_per_step", "version")


def test_groups_cover_every_registered_filter():
    covered = {name for *_, filters in GROUPS for name in filters}
    assert covered == set(FILTERS.builtin), set(FILTERS.builtin) ^ covered  # plugins aside


def _rows(path):
    with open(path, newline="") as fh:
        return {r["filter"]: {k: v for k, v in r.items() if k not in TIMING} for r in csv.DictReader(fh)}


def _campaign(path, dataset, dparams, first, task, filters):
    lines = ["[campaign]", 'name = "eq"', f"runs = {RUNS}", f"seed = {SEED}", "batch = 2", 'alignment = "se3"',
             "", "[[dataset]]", f'id = "{dataset}"', f'tasks = ["{task}"]']
    if dparams:
        lines.append("params = " + "{ " + ", ".join(f"{k} = {json.dumps(v)}" for k, v in dparams.items()) + " }")
    if first:
        lines.append(f"first = {first}")
    for name, params in filters.items():
        lines += ["", "[[filter]]", f'name = "{name}"']
        if params:
            lines.append("params = { " + ", ".join(f"{k} = {json.dumps(v)}" for k, v in params.items()) + " }")
    path.write_text("\n".join(lines) + "\n")
    return path


@pytest.mark.slow
@pytest.mark.parametrize("group", GROUPS, ids=IDS)
def test_eval_and_campaign_give_identical_rows(tmp_path, group):
    dataset, dparams, first, task, filters = group
    args = ["eval", dataset, "--task", task, "--filters", ",".join(filters), "--runs", str(RUNS),
            "--seed", str(SEED), "--out", str(tmp_path / "eval")]
    args += [f"--dataset-param={k}={json.dumps(v)}" for k, v in dparams.items()]
    args += ["--first", str(first)] if first else []
    for name, params in filters.items():
        args += [f"-p{name}.{k}={json.dumps(v)}" for k, v in params.items()]
    runner = CliRunner()
    res = runner.invoke(main, args, catch_exceptions=False)
    assert res.exit_code == 0, res.output
    ev = _rows(tmp_path / "eval" / "leaderboard.csv")
    assert list(ev)[: len(filters)] == list(filters) and set(ev) - set(filters) <= {"measurements"}
    rows = {name: filters.get(name, {}) for name in ev}  # with eval's own baseline row, where the task gives one
    camp = _campaign(tmp_path / "c.toml", dataset, dparams, first, task, rows)
    res = runner.invoke(main, ["campaign", "run", str(camp), "-o", str(tmp_path / "camp"), "-w", "1", "-q"],
                        catch_exceptions=False)
    assert res.exit_code == 0, res.output
    cp = _rows(tmp_path / "camp" / "leaderboard.csv")
    assert list(cp) == list(ev)
    for name in rows:
        assert ev[name] == cp[name], name
        assert ev[name]["runs"] == str(RUNS)
    if "pf" in filters:  # the roughening parameter reached the filter through both doors
        assert json.loads(ev["pf"]["params"])["roughening"] == 0.5


def test_block_composition_does_not_change_a_run():
    """Runs computed in one block or in blocks of one give bit-identical records."""
    cfg = Config("sim/auv-sonar", {"steps": 25}, None, "sonar", {}, "pf",
                 {"n_particles": 100, "resampling": "systematic", "ess_threshold": 1.0, "roughening": 0.3}, 2)
    whole = run_block(cfg, [0, 1, 2])
    alone = [run_block(cfg, [r])[0] for r in (0, 1, 2)]
    for a, b in zip(whole, alone):
        assert a.status == b.status == "done"
        for k in ("pos_rmse", "ate", "nees", "yaw_rmse"):
            assert a.metrics[k] == b.metrics[k], k
        np.testing.assert_array_equal(a.series["x0"], b.series["x0"])


def test_config_hash_is_canonical():
    a = {"dataset": "d", "filter_params": {"b": 1, "a": (1.0, 2.0)}, "seed": np.int64(3)}
    b = {"seed": 3, "filter_params": {"a": [1.0, 2.0], "b": 1}, "dataset": "d"}
    assert config_hash(a) == config_hash(b) and len(config_hash(a)) == 16
    assert config_hash(a) != config_hash(dict(b, seed=4))


def test_eval_manifest_records_the_config_hashes_of_its_rows(tmp_path):
    res = CliRunner().invoke(main, ["eval", "sim/auv-sonar", "--filters", "ekf,ckf", "--runs", "2",
                                    "--dataset-param", "steps=20", "--out", str(tmp_path)], catch_exceptions=False)
    assert res.exit_code == 0, res.output
    man = json.loads((Path(tmp_path) / "manifest.json").read_text())
    rows = _rows(Path(tmp_path) / "leaderboard.csv")
    assert {n: rows[n]["config_hash"] for n in rows} == man["config"]["config_hashes"]
    # the paired column against the first filter, empty in its own row
    assert rows["ekf"]["pos_rmse_vs_ekf"] == "" and float(rows["ckf"]["pos_rmse_vs_ekf_ci95"]) >= 0


def test_manifest_command_repeats_the_evaluation(tmp_path):
    """The manifest's command names the non-default dataset and filter parameters: run, it gives the same rows."""
    import shlex

    args = ["eval", "sim/ungm", "--filters", "ekf,pf", "--runs", "2", "--dataset-param", "q=10",
            "-p", "pf.n_particles=60", "--out", str(tmp_path / "a")]
    res = CliRunner().invoke(main, args, catch_exceptions=False)
    assert res.exit_code == 0, res.output
    command = json.loads((tmp_path / "a" / "manifest.json").read_text())["command"]
    assert "--dataset-param q=10.0" in command and "-p pf.n_particles=60" in command
    assert "steps=" not in command and "resampling" not in command  # defaults are not repeated
    again = shlex.split(command)[1:] + ["--out", str(tmp_path / "b")]
    res = CliRunner().invoke(main, again, catch_exceptions=False)
    assert res.exit_code == 0, res.output
    assert _rows(tmp_path / "a" / "leaderboard.csv") == _rows(tmp_path / "b" / "leaderboard.csv")


def test_a_file_is_read_once_for_all_its_views(tmp_path, monkeypatch):
    """A tune's training segment, test segment and whole-recording rows are cut from one read of the
    file (it was read, for a bag decoded, once per view), each equal to the registry's own load."""
    from replay.data import registry
    from replay.run import pipeline

    log = tmp_path / "lake.csv"
    res = CliRunner().invoke(main, ["datasets", "make", "sim/lake-depth", "--out", str(log), "--seed", "0"])
    assert res.exit_code == 0, res.output
    real, reads = registry.load_frame, []
    monkeypatch.setattr(registry, "load_frame", lambda *a, **kw: reads.append(kw) or real(*a, **kw))
    pipeline.forget_frames()
    views = [{"segment": "0:0.6"}, {"segment": "0.6:1"}, {}, {"window": "10:50"}]
    for first in (None, 30):
        for v in views:
            cfg = {"dataset": str(log), "dataset_params": v,
                   "first": first, "seed": 0, "adapter": "lake"}
            got = pipeline.load_frame(cfg, 0)
            want = real(str(log), adapter="lake", first=first, **v)
            assert len(got.t) == len(want.t) and np.array_equal(got.t, want.t)
            for k, c in want.channels.items():
                assert np.array_equal(np.asarray(got.channels[k].values), np.asarray(c.values), equal_nan=True)
            assert got.meta.get("view") == want.meta.get("view")
    assert len(reads) == 1 and reads[0] == {"data_dir": None, "adapter": "lake"}
    full = pipeline.load_frame({"dataset": str(log), "dataset_params": {}, "first": None, "seed": 0,
                                "adapter": "lake"}, 0)
    assert len(full.t) == len(real(str(log), adapter="lake").t)  # the cached read was not cut in place
    pipeline.forget_frames()


def test_a_file_frame_is_read_again_when_the_file_changes(tmp_path, monkeypatch):
    """A file's frame is read once per process while the file is unchanged; an edit (size, or
    mtime with the same size) or a replacement (new inode) reads it again."""
    import os

    from replay.run import pipeline


    from replay.data import registry

    reads = []
    monkeypatch.setattr(registry, "load_frame", lambda dataset, **kw: reads.append(Path(dataset).read_text()) or
                        len(reads))
    pipeline.forget_frames()
    path = tmp_path / "log.csv"
    path.write_text("a,b\n1,2\n")
    cfg = {"dataset": str(path), "dataset_params": {}, "first": None, "seed": 0}
    assert [pipeline.load_frame(cfg, r) for r in range(3)] == [1, 1, 1]
    path.write_text("a,b\n1,2\n3,4\n")  # longer
    assert pipeline.load_frame(cfg, 3) == 2
    st = path.stat()
    path.write_text("a,b\n1,2\n5,6\n")  # as long; another mtime
    os.utime(path, ns=(st.st_atime_ns, st.st_mtime_ns + 1_000_000))
    assert pipeline.load_frame(cfg, 4) == 3
    new = tmp_path / "new.csv"
    new.write_text("a,b\n1,2\n7,8\n")
    os.utime(new, ns=(st.st_atime_ns, path.stat().st_mtime_ns))
    os.replace(new, path)  # same size and mtime, another file
    assert pipeline.load_frame(cfg, 5) == 4 and pipeline.load_frame(cfg, 6) == 4
    assert reads[-1] == "a,b\n1,2\n7,8\n"
    pipeline.forget_frames()
