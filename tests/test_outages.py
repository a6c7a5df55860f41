"""The outage / resurfacing protocol (issue 35 item 2): fusion ``score=outages``, the end-of-outage
errors per event with intervals (replay.scoring.outages), on a generated recording with known dives."""
import numpy as np
import pytest
from bohai_synth import track, write as write_bohai
from scipy import stats

import replay
from replay.scoring import outages as scoring
from replay.tasks.outages import events
from replay.util.errors import ReplayError

DIVES = ((60.0, 100.0), (150.0, 200.0), (240.0, 270.0))


def test_events_of_gaps_and_withheld_windows():
    """Fixes at 1 Hz: a natural 20 s gap is one outage; windows of 10 s every 30 s withhold the fixes of
    [20, 30), [50, 60), ...; each first fix after is withheld too and is the event."""
    t = np.arange(0.0, 120.0, 0.5)
    fix = (t % 1 == 0) & ~((t > 70) & (t < 90))  # a gap from 70 to 90 s
    fed, ends, starts = events(t, fix, gap=10.0)
    assert t[ends].tolist() == [90.0] and starts.tolist() == [70.0]
    assert not fed[ends].any() and fed.sum() == fix.sum() - 1
    fed, ends, starts = events(t, fix, gap=10.0, length=10.0, every=30.0)
    assert t[ends].tolist() == [30.0, 60.0, 90.0] and starts.tolist() == [19.0, 49.0, 70.0]
    withheld = t[fix & ~fed]
    # the window [80, 90) falls in the gap; the last one, [110, 120), has no fix after it: no event
    assert set(withheld) == set(range(20, 31)) | set(range(50, 61)) | {90} | set(range(110, 120))
    with pytest.raises(ReplayError, match="outage_every = 10 s must exceed outage = 10 s"):
        events(t, fix, gap=10.0, length=10.0, every=10.0)


@pytest.fixture(scope="module")
def dives_eval(tmp_path_factory):
    path = write_bohai(tmp_path_factory.mktemp("dives") / "dives.csv", 36, "garbage", dives=DIVES)
    return replay.evaluate(
        str(path), adapter="bohai-csv", task="fusion", filters=["ekf"], runs=2, task_params={"score": "outages"}
    )


def test_known_dives_are_the_events_and_never_reach_a_filter(dives_eval):
    ev = dives_eval
    prob = ev.results[0].records[0].problem
    spans = np.array(prob.params["outages"])
    # the last fix before each dive (one second before it) and the first after
    assert np.allclose(spans, [[59, 100], [149, 200], [239, 270]], atol=0.11), spans
    steps = scoring.event_steps(ev)
    assert np.allclose(ev.t[steps], [100, 200, 270], atol=0.11)
    assert np.isnan(prob.z[steps, :2]).all()  # the resurfacing fixes are withheld from every filter
    assert prob.truth_valid.sum() == 3 and ev.rows[0]["scored"] == 3


def test_end_of_outage_errors_per_event_with_intervals(dives_eval):
    """Hold-last-fix (the measurements row) is off by the distance travelled during the dive (the
    known track); the EKF (gyro, attitude) carries the speed through it; intervals: over runs per
    event (0: a deterministic filter), across events for the headline (Student t, scipy's)."""
    ev = dives_eval
    rows, heads = scoring.tables(ev)
    t, east, north, *_ = track()
    at = lambda s: np.array([east[int(round(s * 10))], north[int(round(s * 10))]])  # noqa: E731
    travelled = [np.linalg.norm(at(b) - at(a)) for a, b in ((59, 100), (149, 200), (239, 270))]
    hold = [r for r in rows if r["filter"] == "measurements"]
    assert [r["event"] for r in hold] == [1, 2, 3]
    assert np.allclose([r["error"] for r in hold], travelled, atol=0.8), (hold, travelled)  # fix noise ~0.2 m
    ekf = [r for r in rows if r["filter"] == "ekf"]
    assert all(r["runs"] == 2 and r["error_ci95"] == 0.0 for r in ekf)
    assert all(e["error"] < 0.25 * h["error"] for e, h in zip(ekf, hold)), (ekf, hold)
    for h in heads:
        per = np.array([r["error"] for r in rows if r["filter"] == h["filter"]])
        half = stats.t.ppf(0.975, 2) * per.std(ddof=1) / np.sqrt(3)
        assert h["events"] == 3 and np.isclose(h["mean_error"], per.mean()) and np.isclose(h["mean_error_ci95"], half)
    mean, half, different = scoring.paired(ev, "ekf", "measurements")
    assert mean < 0 and np.isclose(mean, np.mean([e["error"] - h["error"] for e, h in zip(ekf, hold)]))


def test_outages_written_and_refused_without_any(dives_eval, tmp_path):
    from replay.outputs.files import write_all

    write_all(dives_eval, tmp_path / "out")
    lines = (tmp_path / "out" / "outages.csv").read_text().splitlines()
    assert lines[0] == ",".join(scoring.EVENT_COLUMNS) and len(lines) == 1 + 2 * 3
    path = write_bohai(tmp_path / "surface.csv", 36, "garbage")
    with pytest.raises(ReplayError, match="no outage in the recording") as err:
        replay.evaluate(str(path), adapter="bohai-csv", task="fusion", filters=["ekf"], runs=1,
                        task_params={"score": "outages"})
    assert "\n" not in str(err.value)
    ev = replay.evaluate(str(path), adapter="bohai-csv", task="fusion", filters=["ekf"], runs=1,
                         task_params={"score": "outages", "outage": 20.0, "outage_every": 60.0})
    steps = scoring.event_steps(ev)
    first = ev.t[np.flatnonzero(np.isfinite(ev.results[0].records[0].problem.z[:, 0]))[0]]
    assert first == pytest.approx(1.0, abs=0.11)  # the adapter's first fresh fix (the first change)
    assert np.allclose(ev.t[steps], first + np.array([60, 120, 180, 240]), atol=0.11)  # a window's end, each 60 s


@pytest.mark.slow
@pytest.mark.parametrize("name", ["20220822_0_3", "20220822_0_4", "20220822_0_5", "20220822_0_6", "20220625_0_0"])
def test_every_shared_sequence_runs_the_protocol(bohai_dir, name):
    """Bohai: the dives (0_4, 0_6) and 30 s windows every 90 s; per-dive end-of-outage errors with an
    interval per filter. (0_0 has no gyro: the fusion task refuses it whatever the protocol.)"""
    ev = replay.evaluate(f"bohai/{name}", data_dir=bohai_dir, filters=["ekf"], runs=1,
                         task_params={"score": "outages", "outage": 30.0, "outage_every": 90.0})
    rows, heads = scoring.tables(ev)
    assert heads[0]["events"] >= 3 and np.isfinite(heads[0]["mean_error_ci95"])
    assert all(np.isfinite(r["error"]) and r["outage_s"] > 10 for r in rows)
