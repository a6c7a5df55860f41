"""Plugins: entry points of other distributions, ``module:Class`` names, the example plugin, bad plugins.

Distributions are faked on disk (a ``*.dist-info`` with ``METADATA`` and
``entry_points.txt`` beside their modules, on ``sys.path``): importlib.metadata finds
them as it finds installed ones. Nothing is installed.
"""
import csv
import os
import re
import subprocess
import sys
import textwrap
import tomllib
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

import replay
from replay.data import registry
from replay.api import refresh_plugins
from replay.cli import main
from replay.filters import FILTERS, make_filter
from replay.data.plugins import ADAPTERS
from replay.tasks import TASKS, make_task
from replay.util.errors import ReplayError

ROOT = Path(__file__).resolve().parents[1]
EXAMPLE = ROOT / "examples" / "replay-plugin-example"
SONAR = ("sim/auv-sonar", {"steps": 40})


@pytest.fixture(autouse=True)
def _forget_session_names():
    """Classes a test registers for the session (evaluate(filters=[cls])) do not outlive it."""
    before = {id(t): set(t._session) for t in (FILTERS, TASKS)}  # noqa: SLF001
    yield
    for t in (FILTERS, TASKS):
        for name in set(t._session) - before[id(t)]:  # noqa: SLF001
            t.unregister(name)


@pytest.fixture
def dists(tmp_path, monkeypatch):
    """``install(name, entry_points={group: {name: target}}, modules={path: source}, version)``: a fake
    installed distribution (and the module files it points at) on sys.path."""
    site = tmp_path / "site"
    site.mkdir()
    monkeypatch.syspath_prepend(str(site))
    before = set(sys.modules)

    def install(name, entry_points, modules=(), version="0.1", path=None):
        info = site / f"{name.replace('-', '_')}-{version}.dist-info"
        info.mkdir()
        (info / "METADATA").write_text(f"Metadata-Version: 2.1\nName: {name}\nVersion: {version}\n")
        text = "".join(f"[{group}]\n" + "".join(f"{k} = {v}\n" for k, v in eps.items()) + "\n"
                       for group, eps in entry_points.items())
        (info / "entry_points.txt").write_text(text)
        for rel, source in dict(modules).items():
            (site / rel).parent.mkdir(parents=True, exist_ok=True)
            (site / rel).write_text(textwrap.dedent(source))
        if path is not None:
            monkeypatch.syspath_prepend(str(path))
        refresh_plugins()

    yield install
    for name in set(sys.modules) - before:  # forget the fake distributions' modules (and the example's)
        where = str(getattr(sys.modules[name], "__file__", "") or "")
        if where.startswith((str(site), str(EXAMPLE))):
            sys.modules.pop(name, None)
    refresh_plugins()


@pytest.fixture
def example(dists):
    """The example plugin as if installed (its entry points from its own pyproject.toml)."""
    eps = tomllib.loads((EXAMPLE / "pyproject.toml").read_text())["project"]["entry-points"]
    dists("replay-plugin-example", eps, version="0.1.0", path=EXAMPLE / "src")


def listing(*args):
    return CliRunner().invoke(main, ["list", *args])


# ---------------------------------------------------------------- the example plugin

def test_example_plugin_is_listed_with_its_origin(example):
    res = listing("filters")
    assert res.exit_code == 0, res.output
    line = next(x for x in res.output.splitlines() if x.startswith("example-filter"))
    assert line.endswith("(plugin: replay-plugin-example 0.1.0)")
    assert "    iterations = 5: an integer in [1, 100]. " in res.output
    assert "ukf " in res.output and FILTERS.origin("ukf") == "built-in"
    assert "(plugin: replay-plugin-example 0.1.0)" in listing("tasks", "example-range-bearing").output
    assert "(plugin: replay-plugin-example 0.1.0)" in listing("datasets", "example/range-bearing").output
    out = listing("plugins").output.splitlines()
    assert [line.split()[:3] for line in out] == [["example-filter", "filter", "from"],
                                                  ["example-range-bearing", "task", "from"],
                                                  ["example/range-bearing", "dataset", "from"]]


def test_example_plugin_runs_beside_the_built_ins(example):
    ev = replay.evaluate("example/range-bearing", filters=["ekf", "example-filter"], runs=3, seed=1,
                         dataset_params={"steps": 150})
    assert [r["filter"] for r in ev.rows] == ["ekf", "example-filter"]
    assert ev.config["task"] == "example-range-bearing"  # the dataset's default task, from the plugin
    ekf, iekf = (r["pos_rmse"] for r in ev.rows)
    assert 3.0 < iekf < 25.0 and 3.0 < ekf < 25.0 and ev.rows[1]["diverged"] == 0
    assert iekf <= ekf * 1.02  # iterating the update never does much worse than one step


def test_example_plugin_in_a_campaign(example, tmp_path):
    path = tmp_path / "c.toml"
    path.write_text('[campaign]\nname = "plugin"\nruns = 2\n\n[[dataset]]\nid = "example/range-bearing"\n'
                    'tasks = ["example-range-bearing"]\nparams = { steps = 60 }\n\n[[filter]]\nname = "ekf"\n\n'
                    '[[filter]]\nname = "example-filter"\nparams = { iterations = 2 }\n')
    board = replay.run_campaign(path, out=tmp_path / "out", workers=1)
    assert board["filter"].tolist() == ["ekf", "example-filter"] and board.attrs["counts"]["failed"] == 0
    ev = replay.evaluate("example/range-bearing", filters="ekf,example-filter", runs=2, dataset_params={"steps": 60},
                         filter_params={"example-filter": {"iterations": 2}})
    assert board["pos_rmse"].tolist() == [r["pos_rmse"] for r in ev.rows]  # campaign and eval: one pipeline


def test_example_filter_batch_equals_runs_of_one(example):
    """The exactness rule of the filter protocol: M runs at once give the numbers of M runs of one."""
    from replay.run.pipeline import build_problem

    flt = make_filter("example-filter", iterations=3)
    problems = [build_problem({"dataset": "example/range-bearing", "dataset_params": {"steps": 60}, "first": None,
                               "task": "example-range-bearing", "task_params": make_task("example-range-bearing").params(),
                               "seed": 2, "adapter": None}, run) for run in range(3)]
    Z = np.stack([p.z for p in problems])
    X0, P0 = np.stack([p.x0 for p in problems]), np.stack([p.P0 for p in problems])
    batch = flt.run_batch(problems[0].model, Z, X0, P0, [None] * 3)
    for m, p in enumerate(problems):
        one = flt.run(p.model, p.z, p.x0, p.P0)
        np.testing.assert_array_equal(batch[m].x, one.x)
        assert batch[m].info["iterations"] == one.info["iterations"] > 60


@pytest.mark.slow
def test_example_filter_by_module_and_class_without_installing(tmp_path):
    """``--filters module:Class`` with the example's source on the path: nothing installed."""
    env = {**os.environ, "PYTHONPATH": str(EXAMPLE / "src")}
    out = tmp_path / "o"
    res = subprocess.run([sys.executable, "-m", "replay.cli", "eval", "sim/auv-sonar", "--dataset-param", "steps=40",
                          "--filters", "ukf,replay_plugin_example.iekf:IteratedEKF", "--runs", "3", "-o", str(out)],
                         capture_output=True, text=True, env=env, cwd=tmp_path, timeout=300)
    assert res.returncode == 0, res.stderr
    with open(out / "leaderboard.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert [r["filter"] for r in rows] == ["ukf", "replay_plugin_example.iekf:IteratedEKF"]
    sys.path.insert(0, str(EXAMPLE / "src"))
    try:
        ev = replay.evaluate("sim/auv-sonar", filters="ukf,replay_plugin_example.iekf:IteratedEKF", runs=3,
                             dataset_params={"steps": 40})
    finally:
        sys.path.remove(str(EXAMPLE / "src"))
    assert float(rows[1]["pos_rmse"]) == pytest.approx(ev.rows[1]["pos_rmse"], rel=1e-5)


# ---------------------------------------------------------------- module:Class names and the session

def test_module_class_names_resolve():
    assert make_filter("replay.filters.sigma:UKF", alpha=1.0).alpha == 1.0
    assert "replay.filters.sigma:UKF" in FILTERS and "replay.filters.sigma:UKF" not in list(FILTERS)
    assert make_task("replay.tasks.sonar:SonarTask").name == "sonar"
    with pytest.raises(ReplayError, match=r"^filter 'nope\.mod:X': cannot be imported: ModuleNotFoundError: "
                                          r"No module named 'nope'$"):
        make_filter("nope.mod:X")
    with pytest.raises(ReplayError, match=r"^filter 'replay\.filters\.base:numerical': is the function numerical, "
                                          r"not a subclass of replay\.filters\.base\.Filter$"):
        make_filter("replay.filters.base:numerical")
    with pytest.raises(ReplayError, match=r"^unknown filter 'nope' \(known: aukf, .* or a 'module:Class' name\)$"):
        make_filter("nope")


def test_every_built_in_passes_the_plugin_checks():
    for table in (FILTERS, TASKS, ADAPTERS):
        for name in table.builtin:
            assert table._check(table.load(name)) is None, name  # noqa: SLF001


def test_filter_classes_and_instances_in_evaluate():
    from replay.filters.sigma import UKF

    class Wider(UKF):
        """A UKF with wider sigma points (a notebook's class)."""

    ev = replay.evaluate("sim/auv-sonar", filters=["ukf", Wider(alpha=1.0)], runs=2, dataset_params={"steps": 40})
    assert [r["filter"] for r in ev.rows] == ["ukf", "wider"]
    assert ev.config["filter_params"]["wider"]["alpha"] == 1.0
    assert FILTERS.origin("wider") == "registered in this session"
    ukf = next(r for r in ev.results if r.name == "ukf")
    assert ev.rows[1]["pos_rmse"] != ev.rows[0]["pos_rmse"] and ukf.params["alpha"] == 0.5
    with pytest.raises(ReplayError, match="filter name 'ukf' is taken by the built-in filter"):
        replay.register_filter(Wider, name="ukf")
    FILTERS.unregister("wider")
    assert "wider" not in FILTERS


# ---------------------------------------------------------------- bad plugins: one line, built-ins unaffected

GOOD = """
from replay.filters import Filter, Param
class Good(Filter):
    '''A good plugin filter.'''
    name = "good"
    PARAMS = (Param("gain", float, 1.0, "a gain", low=0.0),)
    def predict(self, state, k):
        state.x = state.model.f(state.x, k)
        state.P = state.P + state.model.process_cov(k)
    def update(self, state, z, k, mask):
        pass
"""
BAD = {
    "notfilter": ("class NotFilter:\n    pass\n", "NotFilter",
                  "is the class NotFilter, not a subclass of replay.filters.base.Filter"),
    "nomethods": ("from replay.filters import Filter\nclass NoMethods(Filter):\n    pass\n", "NoMethods",
                  r"does not implement engine\(\) or predict\(\)/update\(\)"),
    "badparams": ("from replay.filters import Filter, Param\nclass BadParams(Filter):\n"
                  "    PARAMS = (Param('n', int, 0, 'particles', low=1),)\n    def engine(self, model, rngs):\n"
                  "        pass\n", "BadParams",
                  r"parameter 'n': its default is refused by its own declaration \(n must be an integer >= 1 \(got 0\)\)"),
    "twice": ("from replay.filters import Filter, Param\nclass Twice(Filter):\n"
              "    PARAMS = (Param('a', float, 1.0, 'x'), Param('a', float, 2.0, 'y'))\n"
              "    def engine(self, model, rngs):\n        pass\n", "Twice", "parameter 'a' is declared twice"),
    "raises": ("raise RuntimeError('boom at import')\n", "X", "cannot be imported: RuntimeError: boom at import"),
    "positional": ("from replay.filters import Filter\nclass Positional(Filter):\n"
                   "    def __init__(self, a, **params):\n        super().__init__(**params)\n"
                   "    def engine(self, model, rngs):\n        pass\n", "Positional",
                   r"its constructor takes positional parameters \(a\): parameters are keyword-only"),
}


@pytest.mark.parametrize("name", sorted(BAD))
def test_a_bad_filter_plugin_is_one_line_and_the_others_work(dists, name):
    source, cls, message = BAD[name]
    dists("good-dist", {"replay.filters": {"good": "goodmod:Good"}}, {"goodmod.py": GOOD})
    dists(f"bad-{name}", {"replay.filters": {name: f"bad_{name}:{cls}"}}, {f"bad_{name}.py": source}, version="2.0")
    where = rf"filter '{name}' \(entry point of bad-{name} 2\.0, bad_{name}:{cls}\): "
    with pytest.raises(ReplayError, match=rf"^{where}{message}$"):
        make_filter(name)
    assert type(make_filter("ukf")).__name__ == "UKF" and make_filter("good", gain=2.0).gain == 2.0
    res = CliRunner().invoke(main, ["list", "filters"])
    assert res.exit_code == 0
    warnings = [x for x in res.output.splitlines() if x.startswith("replay: warning: ")]
    assert len(warnings) == 1 and re.search(where + message, warnings[0])
    names = {x.split()[0] for x in res.output.splitlines() if x and not x.startswith((" ", "replay:"))}
    assert names == set(FILTERS.builtin) | {"good"}
    res = CliRunner().invoke(main, ["eval", "sim/auv-sonar", "--filters", f"ukf,{name}", "--runs", "1"])
    assert res.exit_code == 2 and res.output.count("\n") == 1 and re.search(where + message, res.output)


def test_two_distributions_one_name(dists):
    dists("first-dist", {"replay.filters": {"dup": "goodmod:Good"}}, {"goodmod.py": GOOD})
    dists("second-dist", {"replay.filters": {"dup": "goodmod:Good"}}, version="3.1")
    line = ("filter 'dup' is registered twice (entry point of first-dist 0.1, goodmod:Good; entry point of "
            "second-dist 3.1, goodmod:Good): neither is used; uninstall one")
    assert FILTERS.problems() == [line]
    with pytest.raises(ReplayError, match=re.escape(line)):
        make_filter("dup")
    assert "dup" not in list(FILTERS) and make_filter("ekf").name == "ekf"
    table = replay.list_plugins()
    assert table.to_dict("records") == [{"kind": "filter", "name": "", "origin": "", "target": "", "problem": line}]


def test_names_taken_or_unusable_and_bad_targets(dists):
    dists("grabby", {"replay.filters": {"ukf": "goodmod:Good", "a,b": "goodmod:Good", "fine": "goodmod"},
                     "replay.tasks": {"sonar": "goodmod:Good"}}, {"goodmod.py": GOOD})
    assert sorted(FILTERS.problems()) == [
        "filter 'a,b' (entry point of grabby 0.1, goodmod:Good): not a usable filter name; ignored",
        "filter 'fine' (entry point of grabby 0.1, goodmod): the target must be 'module:attribute'; ignored",
        "filter 'ukf' (entry point of grabby 0.1, goodmod:Good): the name is taken by the built-in filter; ignored"]
    assert TASKS.problems() == ["task 'sonar' (entry point of grabby 0.1, goodmod:Good): the name is taken by the "
                                "built-in task; ignored"]
    assert type(make_filter("ukf")).__module__ == "replay.filters.sigma"


def test_broken_metadata_is_one_line(monkeypatch):
    import importlib.metadata

    def boom(**_):
        raise ValueError("bad METADATA")

    monkeypatch.setattr(importlib.metadata, "entry_points", boom)
    refresh_plugins()
    try:
        assert FILTERS.problems() == ["replay.filters: the installed entry points cannot be read "
                                      "(ValueError: bad METADATA)"]
        assert make_filter("ekf").name == "ekf" and "sim/ungm" in registry.all_datasets()
    finally:
        monkeypatch.undo()
        refresh_plugins()


TASK_AND_SIM = """
import numpy as np
from replay.frame import Channel, Frame
from replay.sim import generator
from replay.util.params import Param

@generator((Param("steps", int, 5, "samples", low=1),))
def make(rng, *, steps):
    '''Five samples of nothing.'''
    return Frame(np.arange(steps, dtype=float), {}, {"position": Channel(np.zeros((steps, 2)), "m")})

def undeclared(rng):
    return None

class NotTask:
    pass

def load(path, *, scale=1.0):
    '''Read a one-column text file.'''
    v = np.loadtxt(path) * scale
    return Frame(np.arange(len(v), dtype=float), {"v": Channel(v, "m")})

def bad_load(*, path):
    pass
"""


def test_task_adapter_and_dataset_plugins(dists, tmp_path):
    dists("mixed", {"replay.tasks": {"not-task": "mixmod:NotTask"},
                    "replay.adapters": {"one-column": "mixmod:load", "bad-adapter": "mixmod:bad_load"},
                    "replay.datasets": {"mix/five": "mixmod:make", "mix/undeclared": "mixmod:undeclared",
                                        "mix/missing": "nomod:make", "sim/ungm": "mixmod:make",
                                        "mix/file": "mixmod:NotTask"}},
          {"mixmod.py": TASK_AND_SIM}, version="1.2")
    with pytest.raises(ReplayError, match=r"^task 'not-task' \(entry point of mixed 1\.2, mixmod:NotTask\): is the "
                                          r"class NotTask, not a subclass of replay\.tasks\.Task$"):
        make_task("not-task")
    data = tmp_path / "v.txt"
    data.write_text("1\n2\n3\n")
    frame = registry.load_frame(str(data), adapter="one-column", scale=2.0)
    assert frame.channels["v"].values.tolist() == [2.0, 4.0, 6.0]
    with pytest.raises(ReplayError, match=r"^adapter 'bad-adapter' \(entry point of mixed 1\.2, mixmod:bad_load\): "
                                          r"must take the path as its first parameter"):
        registry.load_frame(str(data), adapter="bad-adapter")
    assert len(registry.load_frame("mix/five", rng=0, steps=3)) == 3
    ds = registry.get("mix/five")
    assert (ds.kind, ds.description, ds.manifest) == ("sim", "Five samples of nothing.",
                                                       "entry point of mixed 1.2, mixmod:make")
    problems = registry.plugin_problems()
    assert sorted(problems) == sorted([
        "dataset 'mix/undeclared' (entry point of mixed 1.2, mixmod:undeclared): declares no parameters "
        "(decorate the simulator with replay.sim.generator)",
        "dataset 'mix/missing' (entry point of mixed 1.2, nomod:make): cannot be imported: ModuleNotFoundError: "
        "No module named 'nomod'",
        "dataset 'mix/file' (entry point of mixed 1.2, mixmod:NotTask): is the class NotTask: neither a simulator "
        "(a function decorated with replay.sim.generator) nor a dict of manifest fields",
        "dataset 'sim/ungm' (entry point of mixed 1.2, mixmod:make): the id is taken by a dataset of replay's "
        "manifests; ignored"])
    assert registry.get("sim/ungm").generator == "replay.sim.ungm:make_frame"  # the built-in one
    res = CliRunner().invoke(main, ["list", "datasets"])
    assert res.exit_code == 0 and res.output.count("replay: warning: dataset ") == 4
    assert "mix/five" in res.output and "sim/auv-sonar" in res.output


def test_dataset_plugin_as_manifest_fields(dists, tmp_path):
    dists("recordings", {"replay.datasets": {"rec/one": "recmod:ONE", "rec/bad": "recmod:BAD"}},
          {"recmod.py": "ONE = {'file': 'one.csv', 'adapter': 'bohai-csv', 'description': 'a recording'}\n"
                        "BAD = {'file': 'bad.csv'}\n"})
    ds = registry.get("rec/one")
    assert (ds.kind, ds.file, ds.adapter) == ("file", "one.csv", "bohai-csv")
    assert registry.plugin_problems() == [
        "entry point of recordings 0.1, recmod:BAD: dataset rec/bad: a file dataset needs an `adapter`"]


# ---------------------------------------------------------------- FilterPy (docs/plugins.md)

def test_filterpy_wrapper_is_the_documented_one_and_short():
    code = (ROOT / "examples" / "filterpy_ukf.py").read_text()
    doc = (ROOT / "docs" / "plugins.md").read_text()
    block = re.search(r"```python\n(import numpy as np\nfrom filterpy.*?)```", doc, re.S).group(1)
    assert block == code and len(code.splitlines()) < 40


def test_filterpy_wrapper_is_exact_on_a_linear_model_and_runs_in_evaluate(monkeypatch):
    pytest.importorskip("filterpy")
    monkeypatch.syspath_prepend(str(ROOT / "examples"))
    from filterpy_ukf import FilterPyUKF

    from replay.model import LinearGaussian

    A = np.array([[1.0, 1.0], [0.0, 1.0]])
    model = LinearGaussian(A, [[1.0, 0.0]], np.diag([0.01, 0.02]), [[0.5]])
    rng = np.random.default_rng(1)
    z = rng.standard_normal((50, 1)) + np.arange(50)[:, None] * 0.3
    z[10] = np.nan  # predict only
    a = FilterPyUKF().run(model, z, np.zeros(2), np.eye(2))
    b = make_filter("kf").run(model, z, np.zeros(2), np.eye(2))
    assert np.abs(a.x - b.x).max() < 1e-12 and np.abs(a.P - b.P).max() < 1e-12
    ev = replay.evaluate("sim/auv-sonar", filters=["ukf", FilterPyUKF], runs=2, dataset_params={"steps": 40})
    assert ev.rows[1]["filter"] == "filterpy-ukf"
    assert ev.rows[1]["pos_rmse"] == pytest.approx(ev.rows[0]["pos_rmse"], rel=1e-9)  # the same UKF
    assert ev.rows[1]["anis"] == pytest.approx(ev.rows[0]["anis"], rel=1e-9)  # its NIS, through state.innovation


def test_filterpy_wrapper_on_partly_missing_bag_measurements(shared_dir, monkeypatch):
    """gps-odom on a real bag: fixes and odometry arrive apart (partly missing z at most steps). The
    first 600 steps (the whole 60 s cost 4x as much in FilterPy's Python for the same assertions)."""
    pytest.importorskip("filterpy")
    monkeypatch.syspath_prepend(str(ROOT / "examples"))
    from filterpy_ukf import FilterPyUKF

    ev = replay.evaluate(shared_dir / "datasets/bags/derived/rl_test1_60s_mcap", task="gps-odom", runs=1, first=600,
                         filters=["ukf", FilterPyUKF], dataset_params={"mapping": ROOT / "docs/mappings/rl_test1_60s.toml"})
    a, b = ev.estimates("ukf"), ev.estimates("filterpy-ukf")
    cols = [c for c in a.columns if c.startswith("x")]
    assert len(a) > 500 and np.abs(a[cols].to_numpy() - b[cols].to_numpy()).max() < 1e-9
    nis_a, nis_b = ev.results[0].runs[0]["nis"], ev.results[1].runs[0]["nis"]
    assert np.isfinite(nis_b) and nis_b == pytest.approx(nis_a, rel=1e-9)
