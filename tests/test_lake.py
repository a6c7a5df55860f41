"""Lake-trial depth logs: the generator, the file format, the adapter, alignment, bad input."""
import numpy as np
import pytest
from click.testing import CliRunner

from replay.data import registry
from replay.adapters.lake import load
from replay.adapters.lake_align import align
from replay.adapters.lake_write import write
from replay.cli import main
from replay.util.errors import DataError, ReplayError
from replay.sim.lake_depth import make_frame, maneuvers


@pytest.fixture(scope="module")
def frame():
    return make_frame(np.random.default_rng(5))


def test_generator_profile_and_noise(frame):
    assert frame.meta["synthetic"] is True
    assert np.diff(frame.t) == pytest.approx(0.05)
    depth = frame.reference["depth"].values
    assert depth.min() > 0.5 and depth.max() - depth.min() > 5  # dives and climbs, never surfaces
    pitch = frame.reference["pitch"].values
    assert np.rad2deg(pitch).max() > 15 and np.rad2deg(pitch).min() < -20
    err = frame.channels["depth"].values - depth
    q = len(err) // 4  # regimes (1, 3, 0.5, 2): the second quarter is noisiest, the third quietest
    stds = [err[i * q:(i + 1) * q].std() for i in range(4)]
    assert stds[1] > 2 * stds[0] and stds[2] < stds[0] and stds[3] > stds[0]
    assert [m[2] for m in maneuvers(90.0)][:2] == ["dive", "pitch steps, climb"]


def test_round_trip(frame, tmp_path):
    path = write(frame, tmp_path / "log.csv", comments=["synthetic: true"])
    back = load(path)
    assert back.meta["synthetic"] is True
    np.testing.assert_allclose(back.t, frame.t, atol=1e-9)
    for group in ("channels", "reference"):
        for name in ("depth", "speed", "pitch"):
            a, b = getattr(frame, group)[name], getattr(back, group)[name]
            np.testing.assert_allclose(b.values, a.values, rtol=1e-9, atol=1e-12)
            assert b.unit == a.unit
            np.testing.assert_array_equal(b.valid, a.valid)
    assert back.report.entries == []  # nothing to repair in a full-rate reference


def test_cli_make_and_eval_file(tmp_path):
    out = tmp_path / "lake.csv"
    res = CliRunner().invoke(main, ["datasets", "make", "sim/lake-depth", "--out", str(out), "-s", "3"])
    assert res.exit_code == 0, res.output
    text = out.read_text()
    assert "SYNTHETIC" in text.splitlines()[1]
    fr = load(out)
    al = fr.meta["reference_alignment"]["depth"]
    # reference at half rate: every other sample interpolated; one 2 s gap masked, 0.3 s gap bridged
    assert al["gaps"] == 1 and 39 <= al["in_gaps"] <= 41
    assert al["interpolated"] > 800 and al["exact"] > 800
    res = CliRunner().invoke(main, ["eval", str(out), "--adapter", "lake", "--filters", "ekf,gpf",
                                    "-p", "gpf.n_particles=200", "-p", "gpf.n_grey=20",
                                    "--first", "400", "-o", str(tmp_path / "run")])
    assert res.exit_code == 0, res.output
    assert "task=depth" in res.output and "speed_rmse" in res.output


def test_align_interpolates_short_gaps_and_masks_long_ones():
    tr = np.array([0.0, 0.1, 0.2, 1.2, 1.3])  # a 1.0 s gap between 0.2 and 1.2
    vr = 10 * tr
    t = np.arange(-0.05, 1.45, 0.05)
    v, ok, c = align(t, tr, vr, max_gap=0.5)
    inside = (t >= -1e-9) & (t <= 1.3 + 1e-9)
    gap = (t > 0.2 + 1e-9) & (t < 1.2 - 1e-9)
    np.testing.assert_array_equal(ok, inside & ~gap)
    np.testing.assert_allclose(v[ok], 10 * t[ok], atol=1e-9)  # linear reference: exact
    assert c == {"exact": 5, "interpolated": 3, "in_gaps": gap.sum(), "gaps": 1,
                 "outside": 3}
    # with a longer limit the gap is bridged
    v, ok, c = align(t, tr, vr, max_gap=1.5)
    assert c["gaps"] == 0 and c["in_gaps"] == 0 and ok[inside].all()


def test_reference_on_own_time_axis_and_units(tmp_path):
    p = tmp_path / "own.tsv"
    rows = ["# units: depth=cm", "time_ms\tdepth\tspeed (kn)\tpitch [rad]\tref_time_s\tref_depth_m"]
    for i in range(10):
        rt = f"{0.15 * i:.2f}" if i < 6 else ""
        rd = f"{2 + 0.15 * i:.2f}" if i < 6 else ""
        rows.append(f"{100 * i}\t{200 + 10 * i}\t1\t0.01\t{rt}\t{rd}")
    p.write_text("\n".join(rows) + "\n")
    f = load(p, max_gap=0.2)
    np.testing.assert_allclose(f.t, 0.1 * np.arange(10))
    np.testing.assert_allclose(f.channels["depth"].values, 2 + 0.1 * np.arange(10))
    np.testing.assert_allclose(f.channels["speed"].values, 0.514444)
    ref = f.reference["depth"]
    np.testing.assert_allclose(ref.values[ref.valid], 2 + 0.1 * np.arange(10)[ref.valid], atol=1e-9)
    assert ref.valid.sum() == 8  # 0.8 and 0.9 s are past the last reference sample (0.75 s)


def write_csv(path, header, rows):
    path.write_text("\n".join([header, *rows]) + "\n")
    return path


@pytest.mark.parametrize("header, rows, match", [
    ("depth_m,speed_mps,pitch_deg,ref_depth_m", ["1,1,1,1"], "no time column"),
    ("time_s,depth_furlong,speed_mps,pitch_deg,ref_depth_m", ["0,1,1,1,1"], "column depth_furlong: unit 'furlong'"),
    ("time_s,depth_m,speed_mps,pitch,ref_depth_m", ["0,1,1,1,1"], "column pitch: no unit"),
    ("time_s,depth_m,pitch_rad,ref_time_s,ref_depth_m", ["0,1,20,100,1", "1,1,0,101,1"],
     "column pitch_rad: values reach 20"),
    ("time_s,depth_m,ref_time_s,ref_depth_m", ["0,1,100,1", "1,1,101,1"],
     "column ref_depth_m: reference times 100..101 s do not overlap"),
    ("time_s,depth_m,ref_depth_m", ["0,1,x", "1,1,1"], "column ref_depth_m: non-numeric"),
])
def test_bad_input_one_line_naming_file_and_column(tmp_path, header, rows, match):
    path = write_csv(tmp_path / "bad.csv", header, rows)
    with pytest.raises(DataError, match=match) as err:
        load(path)
    msg = str(err.value)
    assert "\n" not in msg and str(path) in msg


def test_window_longer_than_log_refused(tmp_path):
    f = make_frame(np.random.default_rng(0), duration=2.0)  # 40 samples < window 50
    path = write(f, tmp_path / "short.csv")
    res = CliRunner().invoke(main, ["eval", str(path), "--adapter", "lake", "--filters", "gpf"])
    assert res.exit_code == 2
    line = res.output.strip()
    assert "\n" not in line and str(path) in line and "column depth_m" in line and "window of 50" in line


def test_max_gap_validated(tmp_path, frame):
    path = write(frame, tmp_path / "log.csv")
    with pytest.raises(ReplayError, match="max_gap"):
        load(path, max_gap=0)


def test_eval_sim_lake_depth_three_filters(tmp_path):
    res = CliRunner().invoke(main, ["eval", "sim/lake-depth", "--filters", "gpf,mmpf,ekf", "--first", "300",
                                    "-p", "gpf.n_particles=200", "-p", "gpf.n_grey=20",
                                    "-p", "mmpf.n_particles=200", "-o", str(tmp_path / "r")])
    assert res.exit_code == 0, res.output
    for name in ("gpf", "mmpf", "ekf"):
        assert f"\n{name} " in res.output
    assert registry.get("sim/lake-depth").default_task == "depth"


def test_base_for_rms_puts_the_sensor_noise_at_a_target_level():
    from replay.sim.lake_depth import base_for_rms, make_frame

    target = (0.2, 5.0, np.deg2rad(0.5))
    base = base_for_rms(target)
    frame = make_frame(np.random.default_rng(5), base_sigma=base)
    for c, want in zip(("depth", "speed", "pitch"), target):
        e = frame.channels[c].values - frame.reference[c].values
        assert np.sqrt(np.mean(e * e)) == pytest.approx(want, rel=0.05)  # 1800 samples: ~2 % spread
    # regimes (1, 3, 0.5, 2) times a drift 1 -> 1.5: the RMS factor is 2.373
    assert base[0] == pytest.approx(0.2 / 2.3733, rel=1e-3)


def test_sensor_rms_is_the_generated_noise_level_and_inverts_base_for_rms():
    from replay.sim.lake_depth import BASE_SIGMA, base_for_rms, sensor_rms

    # regimes (1, 3, 0.5, 2) over the quarters: mean square 3.5625; drift 1 -> 1.5: mean square 1 + 1/2 + 1/12
    factor = np.sqrt(3.5625 * (1 + 1 / 2 + 1 / 12))
    assert sensor_rms() == pytest.approx([factor * b for b in BASE_SIGMA], rel=2e-3)
    assert sensor_rms() == pytest.approx((0.118665, 0.118665, 0.0207109), rel=1e-5)  # 1800 samples of 0.05 s
    assert sensor_rms(base_for_rms((0.2, 5.0, 0.5))) == pytest.approx((0.2, 5.0, 0.5), rel=1e-12)
    f = make_frame(np.random.default_rng(3))
    for c, rms in zip(("depth", "speed", "pitch"), sensor_rms()):
        e = f.channels[c].values - f.reference[c].values
        assert np.sqrt(np.mean(e * e)) == pytest.approx(rms, rel=0.05)
