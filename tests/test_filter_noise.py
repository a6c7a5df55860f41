"""Per-filter noise settings (q_scale, r_scale, p0_scale, Q, R, P0: replay.filters.noise_params).

The filter with a setting computes what it computes on a task whose noise is the set one,
bit for bit; configurations without settings keep the hashes they had before the settings
existed; what cannot be right is refused in one line.
"""
import csv
import json

import numpy as np
import pytest
from click.testing import CliRunner

from replay.cli import main
from replay.filters import FILTERS, Filter, make_filter
from replay.filters.kalman import EKF
from replay.filters.noise_params import NAMES, apply, check
from replay.model import LinearGaussian
from replay.models.random_walk import RandomWalkPosition
from replay.run.pipeline import build_problem, config_hash, plain, run_block
from replay.tasks import make_task
from replay.util.errors import ReplayError

SONAR = {"steps": 40}


def _cfg(filter_params, task_params=None, flt="kf", task="position"):
    return dict(dataset="sim/auv-sonar", dataset_params=SONAR, first=None, task=task,
                task_params=plain(make_task(task, **(task_params or {})).params()), filter=flt,
                filter_params=plain(make_filter(flt, **filter_params).params()), seed=3, alignment="se3",
                divergence_threshold=None, adapter=None)


def _estimates(cfg, runs=(0, 1, 2)):
    recs = run_block(cfg, list(runs), keep=True, strict=True)
    return [r.estimates for r in recs], recs


def _same(a, b):
    for x, y in zip(a, b):
        np.testing.assert_array_equal(x.x, y.x)
        np.testing.assert_array_equal(x.P, y.P)


@pytest.mark.parametrize("s", [0.01, 4.0, 250.0])
def test_q_scale_is_the_task_with_q_times_s(s):
    """KF, linear-Gaussian random walk (position task): q_scale = s is the task's q = s, bit for bit."""
    a, _ = _estimates(_cfg({"q_scale": s}))
    b, _ = _estimates(_cfg({}, {"q": s}))
    c, _ = _estimates(_cfg({}))
    _same(a, b)
    assert not np.array_equal(a[0].x, c[0].x)  # it did change something


def test_r_and_p0_replace_and_scale_what_the_filter_sees():
    """R and P0 (replacement, scale): the KF run directly on a model with that R and prior P0."""
    problems = [build_problem(_cfg({}), r) for r in range(2)]
    Z, X0 = np.stack([p.z for p in problems]), np.stack([p.x0 for p in problems])
    P0 = np.stack([p.P0 for p in problems])
    q, r = problems[0].model.Q, problems[0].model.R

    def direct(R, P):
        kf = make_filter("kf")
        return kf.run_batch(RandomWalkPosition(q, R), Z, X0, P, [np.random.default_rng(0)] * 2)

    R1 = np.diag([0.5, 3.0, 7.0])
    _same(_estimates(_cfg({"R": [0.5, 3.0, 7.0]}), (0, 1))[0], direct(R1, P0))
    _same(_estimates(_cfg({"r_scale": 3.0}), (0, 1))[0], direct(r * 3.0, P0))
    _same(_estimates(_cfg({"R": [[2.0, 0.5, 0], [0.5, 2.0, 0], [0, 0, 1.0]]}), (0, 1))[0],
          direct(np.array([[2.0, 0.5, 0], [0.5, 2.0, 0], [0, 0, 1.0]]), P0))
    _same(_estimates(_cfg({"P0": 5.0}), (0, 1))[0], direct(r, np.broadcast_to(5.0 * np.eye(3), P0.shape)))
    _same(_estimates(_cfg({"p0_scale": 0.25}), (0, 1))[0], direct(r, P0 * 0.25))
    # the task's P0 = p0 I3: the filter's P0 = the same matrix is the same run
    _same(_estimates(_cfg({"P0": [2.0, 2.0, 2.0]}), (0, 1))[0], _estimates(_cfg({}, {"p0": 2.0}), (0, 1))[0])
    # a replacement and a scale: the replacement times the scale
    _same(_estimates(_cfg({"R": 2.0, "r_scale": 3.0}), (0, 1))[0], direct(np.eye(3) * 2.0 * 3.0, P0))


def test_the_problem_and_its_model_are_never_changed():
    p = build_problem(_cfg({}), 0)
    Q, R, P0 = p.model.Q.copy(), p.model.R.copy(), p.P0.copy()
    model, P = apply(make_filter("kf", q_scale=9.0, R=[1.0, 2.0, 3.0], p0_scale=2.0), p.model, p.P0[None])
    assert model is not p.model and np.array_equal(model.Q, 9.0 * Q) and np.array_equal(model.R, np.diag([1., 2, 3]))
    assert np.array_equal(P[0], 2.0 * P0)
    assert np.array_equal(p.model.Q, Q) and np.array_equal(p.model.R, R) and np.array_equal(p.P0, P0)
    same_model, same_P = apply(make_filter("kf"), p.model, p.P0)  # no settings: the objects themselves
    assert same_model is p.model and same_P is p.P0


def test_default_configurations_keep_their_hashes():
    """Hashes computed on main before the settings existed (sim/auv-sonar steps=40, position, seed 3)."""
    assert config_hash(_cfg({})) == "b4f59638819c3dc8"
    assert config_hash(_cfg({}, flt="pf")) == "417e5837a3ca8c0b"  # d915cb34f3791fc8 before pf.proposal (issue 34)
    assert config_hash(_cfg({}, flt="ukf")) == "1060d516bc82d9d8"
    assert config_hash(_cfg({}, flt="mmpf")) == "89c2c39f847773b0"
    assert config_hash(_cfg({"q_scale": 1, "Q": None, "r_scale": 1.0})) == "b4f59638819c3dc8"  # = the defaults
    assert make_filter("pf").params() == {"n_particles": 1000, "resampling": "systematic", "ess_threshold": 1.0,
                                          "roughening": 0.0, "proposal": "auto"}
    h = config_hash(_cfg({"q_scale": 0.3}))
    assert h != "b4f59638819c3dc8" and h != config_hash(_cfg({"q_scale": 0.31}))
    assert make_filter("ukf", R=[[2, 0.5], [0.5, 2]]).params()["R"] == [[2.0, 0.5], [0.5, 2.0]]


def test_time_varying_model_scaled_at_every_step_and_replacement_refused():
    class Varying(LinearGaussian):
        def process_cov(self, k):
            return self.Q * (1.0 + k)

        def measurement_cov(self, k):
            return self.R * (2.0 + k)

    m = Varying(np.eye(2), np.eye(2), np.eye(2), np.eye(2))
    new, _ = apply(make_filter("ekf", q_scale=3.0, r_scale=0.5), m, np.eye(2)[None])
    for k in (0, 5):
        assert np.array_equal(new.process_cov(k), m.process_cov(k) * 3.0)
        assert np.array_equal(new.measurement_cov(k), m.measurement_cov(k) * 0.5)
    assert np.array_equal(m.process_cov(5), 6.0 * np.eye(2))  # the original untouched
    with pytest.raises(ReplayError, match=r"^filter 'ekf': Q cannot replace the noise of model Varying, whose "
                                          r"process_cov\(k\) changes with the step; use q_scale$"):
        check(make_filter("ekf", Q=[1.0, 1.0]), m)
    with pytest.raises(ReplayError, match=r"^filter 'ukf': R cannot replace .* measurement_cov"):
        check(make_filter("ukf", R=2.0), m)


def test_depth_model_draws_with_the_scaled_q():
    """The depth model (paper 000) draws its own process noise: its factor follows the new Q."""
    from replay.models.depth import DepthModel

    m = DepthModel()
    new, _ = apply(make_filter("gpf", q_scale=4.0), m, np.eye(3)[None])
    assert np.array_equal(new.Q, 4.0 * m.Q)
    np.testing.assert_allclose(new.draw_noise((20000,), np.random.default_rng(1)).var(axis=0),
                               np.diagonal(new.Q), rtol=0.05)
    assert np.allclose(DepthModel(Q=4.0 * m.Q)._LQ, new._LQ, rtol=0, atol=0)  # noqa: SLF001


def test_a_plugin_filter_gets_the_settings():
    class Plain(EKF):  # declared parameters of its own
        name = "plain-noise"
        PARAMS = ()

    class Own(Filter):  # a constructor and params() of its own
        name = "own-noise"

        def __init__(self, *, gain=1.0):
            self.gain = gain

        def params(self):
            return {"gain": self.gain}

        def engine(self, model, rngs):
            return EKF().engine(model, rngs)

    for cls in (Plain, Own):
        assert {p.name for p in cls.PARAMS} >= set(NAMES)
        assert cls().params() == ({} if cls is Plain else {"gain": 1.0})
        f = cls(q_scale=2.0, P0=[1.0, 2.0, 3.0])
        assert f.params()["q_scale"] == 2.0 and f.params()["P0"] == [1.0, 2.0, 3.0]
        with pytest.raises(ReplayError, match=r"q_scale must be a finite number > 0"):
            cls(q_scale=-1.0)
    FILTERS.register("own-noise", Own)
    try:
        a, _ = _estimates(dict(_cfg({}), filter="own-noise", filter_params={"gain": 1.0, "q_scale": 4.0}), (0,))
        b, _ = _estimates(_cfg({}, {"q": 4.0}, flt="ekf"), (0,))
        _same(a, b)
    finally:
        FILTERS.unregister("own-noise")
    with pytest.raises(TypeError, match="reserved for the per-filter noise settings"):
        class Clash(EKF):
            from replay.util.params import Param
            PARAMS = (Param("Q", float, 1.0, "its own"),)


def _rows(path):
    with open(path, newline="") as fh:
        return list(csv.DictReader(fh))


KEYS = ("config_hash", "params", "runs", "pos_rmse", "pos_rmse_ci95", "pos_rmse_median", "ate", "nees", "nis", "anees",
        "diverged", "lost")


def test_campaign_grid_over_q_scale_gives_the_rows_of_evals(tmp_path):
    scales = [0.25, 1.0, 8.0]
    camp = tmp_path / "c.toml"
    camp.write_text('[campaign]\nname = "noise"\nruns = 3\nseed = 3\n\n[[dataset]]\nid = "sim/auv-sonar"\n'
                    'tasks = ["position"]\nparams = { steps = 40 }\n\n[[filter]]\nname = "kf"\n'
                    f"grid = {{ q_scale = {json.dumps(scales)} }}\n")
    runner = CliRunner()
    res = runner.invoke(main, ["campaign", "run", str(camp), "-o", str(tmp_path / "camp"), "-w", "1", "-q"],
                        catch_exceptions=False)
    assert res.exit_code == 0, res.output
    cp = {r["config_hash"]: r for r in _rows(tmp_path / "camp" / "leaderboard.csv")}
    assert len(cp) == 3
    for s in scales:
        out = tmp_path / f"e{s}"
        res = runner.invoke(main, ["eval", "sim/auv-sonar", "--task", "position", "--dataset-param", "steps=40",
                                   "--filters", "kf", "--runs", "3", "--seed", "3", "-p", f"kf.q_scale={s}",
                                   "--out", str(out)], catch_exceptions=False)
        assert res.exit_code == 0, res.output
        ev = [r for r in _rows(out / "leaderboard.csv") if r["filter"] == "kf"][0]
        assert {k: ev[k] for k in KEYS} == {k: cp[ev["config_hash"]][k] for k in KEYS}
        assert json.loads(ev["params"]) == ({} if s == 1.0 else {"q_scale": s})
        man = json.loads((out / "manifest.json").read_text())
        assert man["config"]["filter_params"]["kf"] == json.loads(ev["params"])
        assert (f"-p kf.q_scale={s}" in man["command"]) == (s != 1.0)


def test_rerun_repeats_a_configuration_with_noise_settings(tmp_path):
    runner = CliRunner()
    res = runner.invoke(main, ["eval", "sim/auv-sonar", "--task", "position", "--dataset-param", "steps=30",
                               "--filters", "kf,pf", "--runs", "2", "-p", "kf.R=[[2,0.5,0],[0.5,2,0],[0,0,1]]",
                               "-p", "pf.n_particles=50", "-p", "pf.q_scale=0.5", "--out", str(tmp_path / "a")],
                        catch_exceptions=False)
    assert res.exit_code == 0, res.output
    res = runner.invoke(main, ["rerun", str(tmp_path / "a" / "manifest.json"), "--out", str(tmp_path / "b")], catch_exceptions=False)
    assert res.exit_code == 0, res.output
    a, b = _rows(tmp_path / "a" / "leaderboard.csv"), _rows(tmp_path / "b" / "leaderboard.csv")
    assert [{k: r[k] for k in KEYS} for r in a] == [{k: r[k] for k in KEYS} for r in b]
    assert json.loads(a[0]["params"]) == {"R": [[2.0, 0.5, 0.0], [0.5, 2.0, 0.0], [0.0, 0.0, 1.0]]}
