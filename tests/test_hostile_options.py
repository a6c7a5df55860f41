"""Run options and adapter options, each declared once (``replay.run.eval_options``,
``replay.adapters.options``), refused in the same one line through the CLI, the Python
API and a campaign file (corpus: tests/hostile.py); ``replay list adapters`` shows them typed.
"""
from __future__ import annotations

import re

import pytest
from hostile import assert_ok, assert_refused, register

import replay
from replay.campaign import spec
from replay.run.eval_options import BY_NAME, DEFAULTS
from replay.util.errors import ReplayError

# (option, bad value for the API and the campaign file, the same on the command line or None)
RUN_CASES = [
    ("runs", 0, "0"), ("runs", 1.5, "1.5"), ("runs", True, None), ("runs", 10 ** 7, str(10 ** 7)),
    ("seed", -1, "-1"), ("seed", 2 ** 63, str(2 ** 63)), ("seed", "3", None),
    ("alignment", "so3", "so3"), ("alignment", "SE3", "SE3"),
    ("divergence_threshold", -1.0, "-1"), ("divergence_threshold", 0.0, "0"),
    ("divergence_threshold", float("inf"), "inf"),
    ("batch", 0, None), ("batch", 2.5, None),
]
CLI_FLAGS = {"runs": "--runs", "seed": "--seed", "alignment": "--alignment",
             "divergence_threshold": "--divergence-threshold", "first": "--first"}


def _api_error(**options) -> str:
    with pytest.raises(ReplayError) as err:
        replay.evaluate("sim/auv-sonar", filters=["ekf"], **options)
    line = str(err.value)
    assert "\n" not in line
    return line


def _toml(value) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float) and value == float("inf"):
        return "inf"
    return repr(value) if not isinstance(value, str) else f'"{value}"'


def _campaign(tmp_path, head: str = "", dataset: str = 'id = "sim/auv-sonar"', data_dir: str = "") -> str:
    path = tmp_path / "c.toml"
    path.write_text(f'[campaign]\nname = "opts"\n{data_dir}{head}\n[[dataset]]\n{dataset}\n\n'
                    '[[filter]]\nname = "ekf"\n')
    return str(path)


@pytest.mark.parametrize("name,bad,text", RUN_CASES)
def test_run_option_refused_alike_by_api_cli_and_campaign(tmp_path, name, bad, text):
    line = _api_error(**{name: bad})
    assert line.startswith(f"{name} must be {BY_NAME[name].accepts()} (got ")
    if text is not None:  # the command line: the same line
        got = assert_refused(["eval", "sim/auv-sonar", "-f", "ekf", CLI_FLAGS[name], text, "-o", tmp_path / "o"],
                             re.escape(name) + " must be")
        assert got == f"replay: error: {line}"
        assert not (tmp_path / "o").exists()
    path = _campaign(tmp_path, f"{name} = {_toml(bad)}\n")
    with pytest.raises(ReplayError) as err:
        spec.load(path)
    assert re.fullmatch(rf"{re.escape(path)}:\d+: \[campaign\]: {re.escape(line)}", str(err.value))


def test_first_refused_alike(tmp_path):
    line = _api_error(first=0)
    assert line == "first must be an integer >= 1 (or null) (got 0)"
    assert_refused(["eval", "sim/auv-sonar", "-f", "ekf", "--first", "0", "-o", tmp_path / "o"], re.escape(line))
    path = _campaign(tmp_path, dataset='id = "sim/auv-sonar"\nfirst = 0')
    with pytest.raises(ReplayError, match=rf"^{re.escape(path)}:\d+: \[\[dataset\]\]: {re.escape(line)}$"):
        spec.load(path)


def test_defaults_come_from_the_declarations(tmp_path):
    c = spec.load(_campaign(tmp_path))
    assert (c.runs, c.seed, c.batch) == (DEFAULTS["runs"], DEFAULTS["seed"], DEFAULTS["batch"]) == (1, 0, 25)
    assert {cfg.alignment for cfg in c.configs} == {DEFAULTS["alignment"]} == {"se3"}
    assert {cfg.divergence_threshold for cfg in c.configs} == {None}
    help_text = assert_ok(["eval", "--help"]).stdout
    assert "[default: se3]" in help_text and "an integer in [1," in help_text


def test_cli_normalises_as_the_api(tmp_path):
    """--divergence-threshold 50 is the float 50.0 of the API: the same configuration hash."""
    out = tmp_path / "o"
    assert_ok(["eval", "sim/auv-sonar", "-f", "ekf", "--dataset-param", "steps=20", "--divergence-threshold", "50",
               "-o", out, "-q"])
    import json

    man = json.loads((out / "manifest.json").read_text())
    assert man["config"]["divergence_threshold"] == 50.0 and isinstance(man["config"]["divergence_threshold"], float)
    ev = replay.evaluate("sim/auv-sonar", filters=["ekf"], dataset_params={"steps": 20}, divergence_threshold=50)
    assert ev.results[0].config_hash == man["config"]["config_hashes"]["ekf"]


# ---------------------------------------------------------------- adapter options

BOHAI_CASES = [
    ({"jump_threshold": 0}, "adapter bohai-csv: jump_threshold must be a finite number > 0 (got 0)"),
    ({"max_speed": -1.5}, "adapter bohai-csv: max_speed must be a finite number > 0 (got -1.5)"),
    ({"gps_tolerance": "far"}, "adapter bohai-csv: gps_tolerance must be a finite number > 0 (or null) (got 'far')"),
    ({"gap_factor": 1}, "adapter bohai-csv: gap_factor must be a finite number > 1 (got 1)"),
    ({"gap_factor": True}, "adapter bohai-csv: gap_factor must be a finite number > 1 (got true)"),
    ({"jump": 3.0}, "adapter bohai-csv: unknown option 'jump' (known: jump_threshold, max_speed, gps_tolerance, "
                    "gap_factor)"),
]


def _assign(params: dict) -> list[str]:
    import json

    return [f"{k}={v if isinstance(v, str) else json.dumps(v)}" for k, v in params.items()]


@pytest.mark.parametrize("params,line", BOHAI_CASES)
def test_bohai_option_refused_alike_by_api_cli_and_campaign(tmp_path, monkeypatch, params, line):
    monkeypatch.delenv("REPLAY_DATA_DIR", raising=False)
    with pytest.raises(ReplayError) as err:  # checked before the file is looked for
        replay.evaluate("bohai/20220822_0_7", filters=["ekf"], dataset_params=params)
    assert str(err.value) == line
    with pytest.raises(ReplayError) as err:
        replay.load_frame("bohai/20220822_0_7", **params)
    assert str(err.value) == line
    args = [a for p in _assign(params) for a in ("--dataset-param", p)]
    assert assert_refused(["eval", "bohai/20220822_0_7", "-f", "ekf", *args, "-o", tmp_path / "o"],
                          re.escape(line)) == f"replay: error: {line}"
    (tmp_path / "d").mkdir()
    (tmp_path / "d" / "20220822_0_7.csv").write_text("a stand-in: the options are refused before it is read\n")
    key, value = next(iter(params.items()))
    path = _campaign(tmp_path, dataset=f'id = "bohai/20220822_0_7"\nparams = {{ {key} = {_toml(value)} }}',
                     data_dir='data_dir = "d"\n')
    with pytest.raises(ReplayError, match=rf"^{re.escape(path)}:\d+: {key}: {re.escape(line)}$"):
        spec.load(path)


def test_adapter_load_itself_refuses(tmp_path):
    from replay.adapters.bags import load as load_bag
    from replay.adapters.bohai import load as load_bohai
    from replay.adapters.lake import load as load_lake

    missing = tmp_path / "never.csv"
    for call, line in [
        (lambda: load_bohai(missing, gap_factor=0.5), "adapter bohai-csv: gap_factor must be a finite number > 1 "
                                                      "(got 0.5)"),
        (lambda: load_lake(missing, max_gap=float("nan")), "adapter lake: max_gap must be a finite number > 0 "
                                                           "(got nan)"),
        (lambda: load_bag(missing, time="utc"), "adapter bags: time must be one of header, log (or null) "
                                                "(got 'utc')"),
        (lambda: load_bag(missing, until=-1), "adapter bags: until must be a finite number > 0 (or null) (got -1)"),
        (lambda: load_bag(missing, water_density=0), "adapter bags: water_density must be a finite number > 0 "
                                                     "(or null) (got 0)"),
        (lambda: load_bag(missing, mapping=5), "adapter bags: mapping must be a mapping file (a path), a dict of "
                                               "the same form or a Mapping (or null) (got 5)"),
        (lambda: load_bag(missing, allow_truncated="yes"), "adapter bags: allow_truncated must be true or false "
                                                           "(or null) (got 'yes')"),
    ]:
        with pytest.raises(ReplayError) as err:
            call()
        assert str(err.value) == line
    assert not missing.exists()


@pytest.fixture(scope="module")
def lake_log(tmp_path_factory):
    log = tmp_path_factory.mktemp("lake") / "lake.csv"
    assert_ok(["datasets", "make", "sim/lake-depth", "--out", log, "--seed", "0"])
    return log


def test_lake_option_refused_alike_by_api_cli_and_campaign(tmp_path, lake_log):
    line = "adapter lake: max_gap must be a finite number > 0 (got 0)"
    with pytest.raises(ReplayError) as err:
        replay.evaluate(str(lake_log), adapter="lake", filters=["ekf"], dataset_params={"max_gap": 0})
    assert str(err.value) == line
    assert_refused(["eval", lake_log, "--adapter", "lake", "-f", "ekf", "--dataset-param", "max_gap=0",
                    "-o", tmp_path / "o"], re.escape(line))
    path = _campaign(tmp_path, dataset=f'id = "{lake_log}"\nparams = {{ max_gap = 0 }}')
    with pytest.raises(ReplayError, match=rf"^{re.escape(path)}:\d+: max_gap: {re.escape(line)}$"):
        spec.load(path)
    a = replay.load_frame(str(lake_log), adapter="lake", max_gap=1)  # an integer is the float 1.0
    b = replay.load_frame(str(lake_log), adapter="lake", max_gap=1.0)
    assert a.meta["reference_alignment"] == b.meta["reference_alignment"]
    assert a.meta["reference_alignment"]["depth"]["max_gap"] == 1.0


def test_list_adapters_bohai_shows_typed_options():
    lines = assert_ok(["list", "adapters", "bohai"]).stdout.splitlines()
    assert lines == [
        "bohai-csv  Read one Bohai CSV log into a Frame.",
        "    jump_threshold = 5.0 [m per 0.1 s]: a finite number > 0. a step of the navigation solution longer "
        "than this is a jump",
        "    max_speed = 10.0 [m/s]: a finite number > 0. the fastest plausible motion of the vehicle",
        "    gps_tolerance = 15.0 [m]: a finite number > 0 (or null). how far a fresh GPS fix may lie from the "
        "navigation solution before it contradicts it (null: no GPS check)",
        "    gap_factor = 5.0: a finite number > 1. a time step longer than this many median steps is flagged "
        "as a gap",
    ]
    assert assert_ok(["list", "adapters", "bohai-csv"]).stdout.splitlines() == lines
    lake = assert_ok(["list", "adapters", "lake"]).stdout.splitlines()
    assert lake[1] == ("    max_gap = 0.5 [s]: a finite number > 0. longest reference gap bridged by linear "
                       "interpolation")
    assert_refused(["list", "adapters", "sim"], r"^replay: error: replay list adapters: no adapter 'sim'")


register("eval-runs-1.5", "eval-runs-abc", "eval-alignment-case", "eval-divergence-threshold-inf",
         "campaign-batch-0", "campaign-dataset-first-0", "adapter-option-out-of-bounds", "adapter-option-unknown",
         "adapter-option-wrong-type", "manifest-seed-negative")


@pytest.mark.parametrize("command", [["reproduce", "002", "--quick"], ["tune", "sim/ungm", "-o", "t"],
                                     ["rerun", __file__]])
def test_a_data_dir_that_is_not_a_directory_is_refused_before_any_work(command, tmp_path):
    """--data-dir is declared once for the commands that run (replay.cli.run_options.DATA_DIR) and a mistyped
    one is refused, not ignored (replay reproduce 002 would otherwise leave out its Bohai rows)."""
    assert_refused([*command, "--data-dir", str(tmp_path / "nowhere")],
                   r"^replay: error: --data-dir .*nowhere: no such directory$", cwd=tmp_path)


def test_run_reproduction_refuses_a_missing_data_dir_from_python(tmp_path):
    from replay.reproduce import run_reproduction

    with pytest.raises(ReplayError, match=r"^data_dir .*nowhere: no such directory$"):
        run_reproduction("002", data_dir=str(tmp_path / "nowhere"), quick=True, doc=str(tmp_path / "002.md"))
    assert not (tmp_path / "002.md").exists()
