"""Injected sensor faults (replay/data/faults.py, fault_apply.py): known answers on a generated
frame, the reference untouched, the same one line from the CLI, a campaign file and the API, and
a faulted run reproduced by replay rerun."""
import json

import numpy as np
import pytest
from click.testing import CliRunner

import replay
from replay.cli import main
from replay.data import fault_apply, faults
from replay.frame import Channel, Frame
from replay.util.errors import ReplayError
from replay.util.seeds import FAULT, rng_for

N = 100


def _frame():
    """1 Hz, 100 samples: gps (2 components) with a companion gps_sigma, odom valid at even samples."""
    t = np.arange(N, dtype=float)
    gps = Channel(np.column_stack([t, 2 * t]), "m", components=("east", "north"))
    sigma = Channel(np.ones((N, 2)), "m")
    odom = Channel(np.where(np.arange(N) % 2 == 0, 0.5 * t, np.nan), "m/s")
    ref = Channel(np.column_stack([t, 2 * t]), "m", components=("east", "north"))
    return Frame(t, {"gps": gps, "gps_sigma": sigma, "odom": odom}, {"position": ref}, None, {"source": "test"})


def _apply(spec, seed=0, frame=None):
    frame = frame or _frame()
    out = fault_apply.apply(frame, [spec] if isinstance(spec, str) else spec, rng_for(seed, 0, FAULT))
    np.testing.assert_array_equal(out.reference["position"].values, frame.reference["position"].values)
    assert out.reference["position"] is frame.reference["position"]  # the reference is never faulted
    assert "faults" not in frame.meta and frame.report.entries == []  # the input frame untouched
    return out


def _counts(out, action):
    return {e.what: e.count for e in out.report.find(action)}


def test_outage_drops_exactly_its_span_and_the_message_companions():
    out = _apply("gps:outage:t0=10,d=5")
    gps = out.channels["gps"]
    assert np.flatnonzero(~gps.valid).tolist() == [10, 11, 12, 13, 14]
    np.testing.assert_array_equal(out.channels["gps_sigma"].valid, gps.valid)  # the same message
    assert out.channels["odom"].valid.sum() == 50  # another channel untouched
    assert _counts(out, "dropped") == {"gps": 5}
    assert out.meta["faults"][0]["channels"] == ["gps", "gps_sigma"]
    rep = _apply("gps:outage:t0=10,d=5,every=20")
    assert (~rep.channels["gps"].valid).sum() == 25 and not rep.channels["gps"].valid[[30, 54, 94]].any()


def test_dropout_is_the_uniform_draw_below_p_and_nested_in_p():
    out = _apply("gps:dropout:p=0.3", seed=4)
    u = rng_for(4, 0, FAULT).spawn(1)[0].random(N)  # the fault's own child stream
    np.testing.assert_array_equal(~out.channels["gps"].valid, u < 0.3)
    assert _counts(out, "dropped") == {"gps": int((u < 0.3).sum())}
    more = _apply("gps:dropout:p=0.5", seed=4)
    assert np.all(more.channels["gps"].valid <= out.channels["gps"].valid)  # lost at 0.3 -> lost at 0.5
    assert np.isnan(out.channels["gps"].values[~out.channels["gps"].valid]).all()


def test_outliers_fixed_jump_has_exactly_that_norm():
    out = _apply("gps:outliers:p=0.2,jump=20", seed=1)
    diff = out.channels["gps"].values - _frame().channels["gps"].values
    norm = np.linalg.norm(diff, axis=1)
    hit = norm > 0
    np.testing.assert_allclose(norm[hit], 20.0)
    assert hit.sum() == _counts(out, "altered")["gps"] == int((rng_for(1, 0, FAULT).spawn(1)[0].random(N) < 0.2).sum())
    t3 = _apply("gps:outliers:p=1,s=2", seed=1)
    assert _counts(t3, "altered") == {"gps": N} and t3.meta["faults"][0]["fault"] == "gps:outliers:p=1,s=2,df=3"


def test_bias_step_per_component_and_scale_and_quantize():
    out = _apply("gps:bias:b=[1.5,-2],t0=50")
    diff = out.channels["gps"].values - _frame().channels["gps"].values
    np.testing.assert_array_equal(diff[:50], 0.0)
    np.testing.assert_array_equal(diff[50:], np.tile([1.5, -2.0], (50, 1)))
    assert _counts(out, "altered") == {"gps": 50}
    one = _apply("gps:bias:b=3")  # one value: every component, from t = 0
    np.testing.assert_array_equal(one.channels["gps"].values - _frame().channels["gps"].values, 3.0)
    odd = _apply("odom:scale:k=2")
    np.testing.assert_array_equal(odd.channels["odom"].values[::2], np.arange(0, N, 2.0))
    assert _counts(odd, "altered") == {"odom": 50}
    q = _apply("odom:quantize:step=2")  # 0.5 t at even t: 0, 1, 2, ...: the odd values change
    assert set(np.unique(q.channels["odom"].values[::2] % 2)) == {0.0} and _counts(q, "altered") == {"odom": 25}


def test_drift_is_a_random_walk_from_t0():
    out = _apply("gps:drift:s=0.5,t0=20", seed=2)
    diff = out.channels["gps"].values - _frame().channels["gps"].values
    np.testing.assert_array_equal(diff[:21], 0.0)  # from t0, starting at zero (no time elapsed yet)
    steps = rng_for(2, 0, FAULT).spawn(1)[0].normal(size=(80, 2)) * 0.5 * np.r_[0.0, np.ones(79)][:, None]
    np.testing.assert_allclose(diff[20:], np.cumsum(steps, axis=0), atol=1e-12)


def test_delay_shifts_the_stamps_and_loses_those_past_the_end():
    out = _apply("gps:delay:d=2")
    gps = out.channels["gps"]
    np.testing.assert_array_equal(gps.values[2:], _frame().channels["gps"].values[:-2])  # data unchanged, later
    assert not gps.valid[:2].any() and out.channels["gps_sigma"].valid[2:].all()
    assert _counts(out, "dropped") == {"gps": 2} and _counts(out, "shifted") == {"gps": 98}
    snapped = _apply("gps:delay:d=2.4")  # onto the nearest stamp, the difference reported
    assert snapped.meta["faults"][0]["largest_stamp_error_s"] == pytest.approx(0.4)
    early = _apply("gps:clock_offset:c=-3")
    np.testing.assert_array_equal(early.channels["gps"].values[:-3], _frame().channels["gps"].values[3:])
    assert _counts(early, "dropped") == {"gps": 3}


def test_jitter_moves_each_sample_by_its_draw():
    out = _apply("gps:jitter:s=1", seed=5)
    e = out.meta["faults"][0]
    assert e["dropped"] + e["valid_after"] == N and e["shifted"] > 0
    again = _apply("gps:jitter:s=1", seed=5)
    np.testing.assert_array_equal(again.channels["gps"].values, out.channels["gps"].values)  # bit-reproducible


def test_rate_decimates_a_channel():
    out = _apply("gps:rate:f=0.25")
    # grid 0, 4, ..., 100: the grid point 100 takes t = 99, within its half period [98, 102)
    assert np.flatnonzero(out.channels["gps"].valid).tolist() == list(range(0, N, 4)) + [99]
    assert _counts(out, "dropped") == {"gps": 74}
    fast = _apply("gps:rate:f=1e300")  # above the channel's rate: nothing dropped (and no grid of 1e300 points)
    assert fast.channels["gps"].valid.all() and _counts(fast, "dropped") == {"gps": 0}


def test_rate_refuses_a_grid_of_more_than_ten_points_per_sample():
    t = np.r_[0.0, 1e-6, np.arange(1.0, 99.0)]  # two samples 1 µs apart: a period of 10 µs decimates them
    f = Frame(t, {"gps": Channel(t, "m")}, {"position": Channel(t, "m")}, None, {})
    with pytest.raises(ReplayError, match=r"^test: fault gps:rate:f=100000: 9800001 grid points over 100 samples"):
        fault_apply.apply(f, ["gps:rate:f=1e5"], rng_for(0, 0, FAULT), "test")


def test_each_fault_has_its_own_stream():
    a = _apply(["gps:dropout:p=0.3", "odom:outliers:p=0.5,s=1"], seed=3)
    b = _apply(["gps:dropout:p=0.6", "odom:outliers:p=0.5,s=1"], seed=3)
    np.testing.assert_array_equal(a.channels["odom"].values, b.channels["odom"].values)


@pytest.mark.parametrize(
    "spec, message",
    [
        ("gps:dropout:p=1", "removes every sample of channel gps (100 valid)"),
        ("gps:outage:t0=0,d=100", "removes every sample of channel gps"),
        ("lidar:dropout:p=0.1", "no channel 'lidar'"),
        ("position:dropout:p=0.1", "a reference channel: faults apply to sensor channels only"),
        ("gps:bias:b=[1,2,3]", "b holds 3 values, the channel has 2 component(s)"),
        ("gps:scale:k=1e308", "makes values of the channel non-finite"),
    ],
)
def test_refused_when_applied(spec, message):
    with pytest.raises(ReplayError, match="^test: fault ") as err:
        fault_apply.apply(_frame(), [spec], rng_for(0, 0, FAULT), "test")
    assert message in str(err.value) and "\n" not in str(err.value)


def test_campaign_fault_table_on_a_missing_channel_is_refused_before_any_unit(tmp_path):
    (tmp_path / "c.toml").write_text(
        '[campaign]\nruns = 1\n\n[[dataset]]\nid = "sim/linear"\n\n[[fault]]\nchannel = "lidar"\n'
        'kind = "dropout"\np = 0.1\n\n[[filter]]\nname = "kf"\n'
    )
    res = CliRunner().invoke(main, ["campaign", "run", str(tmp_path / "c.toml"), "-o", str(tmp_path / "o")])
    assert res.exit_code == 2 and "c.toml:8: fault: sim/linear: fault lidar:dropout:p=0.1: no channel 'lidar'" in res.output
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize(
    "spec, message",
    [
        ("gps:dropout:p=1.5", "p must be a finite number in [0, 1] (got 1.5)"),
        ("gps:burst:p=0.1", "unknown kind 'burst'"),
        ("gps:outage:t0=1", "d is missing"),
        ("gps:outage:t0=1,d=2,x=3", "unknown parameter 'x'"),
        ("gps:outliers:p=0.1", "give either s"),
        ("gps:delay:d=-1", "d must be a finite number > 0"),
        ("gps:outage:t0=1,d=5,every=5", "must be longer than the outage"),
        ("gps", "expected CHANNEL:KIND:NAME=VALUE"),
        ("lidar:dropout:p=0.1", "sim/linear: fault lidar:dropout:p=0.1: no channel 'lidar' (channels: z)"),
        ("z:outage:t0=0,d=1000", "removes every sample of channel z (500 valid)"),
    ],
)
def test_bad_specifications_one_line_in_api_cli_and_campaign(spec, message, tmp_path):
    with pytest.raises(ReplayError) as err:
        replay.load_frame("sim/linear", fault=spec)
    line = str(err.value)
    assert message in line and "\n" not in line
    res = CliRunner().invoke(main, ["eval", "sim/linear", "-f", "kf", "--fault", spec, "-o", str(tmp_path / "e")])
    assert res.exit_code == 2 and line in res.output and "Traceback" not in res.output, res.output
    (tmp_path / "c.toml").write_text(
        f'[campaign]\nruns = 1\n\n[[dataset]]\nid = "sim/linear"\nparams = {{ fault = ["{spec}"] }}\n\n'
        '[[filter]]\nname = "kf"\n'
    )
    res = CliRunner().invoke(main, ["campaign", "run", str(tmp_path / "c.toml"), "-o", str(tmp_path / "c"), "-q"])
    assert res.exit_code == 2 and line in res.output and "Traceback" not in res.output, res.output


def test_canonical_forms_agree():
    table = {"channel": "gps", "kind": "outage", "d": 60, "t0": 120.0}
    assert faults.check(table) == faults.check("gps:outage:t0=120,d=60") == ["gps:outage:t0=120,d=60"]


def test_eval_runs_draw_their_own_faults_and_rerun_reproduces(tmp_path):
    runner = CliRunner()
    out = tmp_path / "e"
    res = runner.invoke(
        main,
        ["eval", "sim/linear", "-f", "kf", "-n", "3", "--dataset-param", "steps=60",
         "--fault", "z:outliers:p=0.2,jump=30", "--fault", "z:outage:t0=20,d=10", "-o", str(out), "-q"],
        catch_exceptions=False,
    )
    assert res.exit_code == 0, res.output
    man = json.loads((out / "manifest.json").read_text())
    assert man["config"]["dataset_params"]["fault"] == ["z:outliers:p=0.2,jump=30", "z:outage:t0=20,d=10"]
    assert [f["fault"] for f in man["dataset"]["faults"]] == man["config"]["dataset_params"]["fault"]
    assert {e["what"]: e["count"] for e in man["adapter_report"] if e["action"] == "dropped"}["z"] == 10
    res = runner.invoke(main, ["rerun", str(out / "manifest.json"), "-q"], catch_exceptions=False)
    assert res.exit_code == 0 and "reproduced" in res.output, res.output
    # each Monte Carlo run draws its own faults, from its fault stream (seed, run, FAULT)
    from replay.run.pipeline import load_frame

    params = dict(man["config"]["dataset_params"])
    cfg = {"dataset": "sim/linear", "dataset_params": params, "first": None, "seed": 0, "adapter": None}
    hits = []
    for run in (0, 1):
        clean = load_frame(dict(cfg, dataset_params={k: v for k, v in params.items() if k != "fault"}), run)
        faulty = load_frame(cfg, run)
        hit = np.linalg.norm(faulty.channels["z"].values - clean.channels["z"].values, axis=1) > 0
        u = rng_for(0, run, FAULT).spawn(2)[0].random(60)
        np.testing.assert_array_equal(hit, (u < 0.2) & ((clean.t < 20) | (clean.t >= 30)))  # then the outage
        hits.append(hit)
    assert not np.array_equal(*hits)


# ---------------------------------------------------------------- sweeps, scores, recovery

def test_campaign_fault_tables_sweep_and_robustness_score(tmp_path):
    from replay.campaign import spec
    from replay.outputs import robustness

    (tmp_path / "c.toml").write_text(
        '[campaign]\nruns = 3\n\n[[dataset]]\nid = "sim/linear"\nparams = { steps = 60 }\n\n'
        '[[fault]]\nchannel = "z"\nkind = "outliers"\njump = 40\nsweep = { p = [0, 0.1, 0.3] }\n\n'
        '[[fault]]\nchannel = "z"\nkind = "outage"\nt0 = 10\nd = 5\n\n[[filter]]\nname = "kf"\n'
    )
    camp = spec.load(tmp_path / "c.toml")
    assert [c.dataset_params["fault"] for c in camp.configs] == [
        [f"z:outliers:p={p},jump=40", "z:outage:t0=10,d=5"] for p in ("0", "0.1", "0.3")
    ]
    res = CliRunner().invoke(main, ["campaign", "run", str(tmp_path / "c.toml"), "-o", str(tmp_path / "o"), "-q"])
    assert res.exit_code == 0, res.output
    rows = replay.campaign_results(tmp_path / "o").to_dict("records")
    (sweep,) = robustness.sweeps(rows)
    assert sweep["parameter"] == "p" and sweep["fault"] == "z:outliers:p=*,jump=40 + z:outage:t0=10,d=5"
    lines, scores = robustness.table(sweep)
    y = [r["pos_rmse"] for r in sorted(lines, key=lambda r: r["p"])]
    assert y[0] < y[1] < y[2]  # more outliers, more error
    assert scores["kf"] == pytest.approx(((y[0] + y[1]) / 2 * 0.1 + (y[1] + y[2]) / 2 * 0.2) / 0.3)
    bad = tmp_path / "bad.toml"
    bad.write_text(
        '[campaign]\nruns = 1\n\n[[dataset]]\nid = "sim/linear"\n\n[[fault]]\nchannel = "z"\nkind = "dropout"\n'
        "sweep = { p = [0.1, 1.5] }\n\n[[filter]]\nname = \"kf\"\n"
    )
    with pytest.raises(ReplayError, match=r"bad.toml:\d+: fault: fault z:dropout: p must be a finite number in \[0, 1\]"):
        spec.load(bad)


def test_robustness_score_and_recovery_time_known_values():
    from replay.outputs.robustness import recovery_time, score

    assert score([(0, 1.0), (10, 3.0), (30, 3.0)]) == pytest.approx((20 + 60) / 30)
    t = np.arange(0, 100.0)
    err = np.full(100, 1.0)
    err[40:60] = 10.0  # the outage [40, 50), the error back below 2 m at t = 60
    err[60:] = 1.5
    assert recovery_time(t, err, 40, 50) == 10.0
    assert np.isnan(recovery_time(t, np.where(t >= 40, 5.0, 1.0), 40, 50))  # never recovers


def test_models_with_a_gate_of_arrays_are_compared_field_by_field():
    # a gated mapping's runs: the model holds a dataclass of arrays; `==` on it raised "truth value ambiguous"
    from dataclasses import dataclass

    from replay.run.pipeline import same_model

    @dataclass
    class Gate:
        threshold: np.ndarray

    class Model:
        def __init__(self, th):
            self.gate, self.n = Gate(np.array(th, float)), 6

    assert same_model(Model([5.0, 5.0]), Model([5.0, 5.0]))
    assert not same_model(Model([5.0, 5.0]), Model([5.0, 4.0]))
    assert not same_model(Model([5.0, 5.0]), Model([5.0, 5.0, 5.0]))


@pytest.mark.slow
def test_report_of_an_outage_sweep_writes_its_table_recovery_and_figures(tmp_path):
    """Slow: a campaign and its report's figures (10-30 s); the fast subset keeps
    test_campaign_fault_tables_sweep_and_robustness_score (the sweep and its table) and
    test_robustness_score_and_recovery_time_known_values (the numbers)."""
    from replay.outputs.report import make_report

    (tmp_path / "c.toml").write_text(
        '[campaign]\nruns = 2\n\n[[dataset]]\nid = "sim/linear"\nparams = { steps = 80 }\n\n'
        '[[fault]]\nchannel = "z"\nkind = "outage"\nt0 = 20\nsweep = { d = [0, 10, 30] }\n\n'
        '[[filter]]\nname = "kf"\n'
    )
    res = CliRunner().invoke(main, ["campaign", "run", str(tmp_path / "c.toml"), "-o", str(tmp_path / "o"), "-q"])
    assert res.exit_code == 0, res.output
    make_report(tmp_path / "o")
    text = (tmp_path / "o" / "report" / "robustness.md").read_text()
    assert "fault z:outage:t0=20,d=*" in text and "| kf |" in text and "recovers in" in text
    assert (tmp_path / "o" / "report" / "degradation_0.png").stat().st_size > 0
    assert (tmp_path / "o" / "report" / "outage_0.png").stat().st_size > 0


KINDS = ["z:dropout:p=0.3", "z:outage:t0=5,d=10,every=20", "z:outliers:p=0.2,s=3,df=3", "z:bias:b=[1,-1,0.5],t0=10",
         "z:drift:s=0.2,t0=5", "z:scale:k=1.5", "z:delay:d=2", "z:jitter:s=1.5", "z:clock_offset:c=-1,skew=2000",
         "z:rate:f=0.5", "z:quantize:step=0.5"]


def test_the_list_covers_every_kind():
    assert sorted(s.split(":")[1] for s in KINDS) == sorted(faults.KINDS)


@pytest.mark.slow
@pytest.mark.parametrize("spec", KINDS)
def test_every_kind_in_the_manifest_and_rerun_exactly(spec, tmp_path):
    runner = CliRunner()
    out = tmp_path / "e"
    res = runner.invoke(main, ["eval", "sim/linear", "-f", "kf", "-n", "2", "--dataset-param", "steps=40",
                               "--fault", spec, "-o", str(out), "-q"], catch_exceptions=False)
    assert res.exit_code == 0, res.output
    man = json.loads((out / "manifest.json").read_text())
    assert man["config"]["dataset_params"]["fault"] == [spec]  # already canonical
    assert man["dataset"]["faults"][0]["fault"] == spec
    assert any(spec in e["reason"] for e in man["adapter_report"])
    res = runner.invoke(main, ["rerun", str(out / "manifest.json"), "-q"], catch_exceptions=False)
    assert res.exit_code == 0 and "reproduced" in res.output, res.output
