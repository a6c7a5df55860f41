"""Built-in filters declare where they are checked (``CASE``, replay.filters.case) and the suite derives
its groups from that: a new built-in filter is one file plus one registry line."""
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from builtin_cases import cases, group_id, groups

from replay.data import dataset_ref
from replay.filters import FILTERS
from replay.filters.case import DEFAULT, Case, case_of
from replay.tasks import TASKS

ROOT = Path(__file__).resolve().parents[1]


def test_every_builtin_case_names_a_simulator_a_task_and_declared_parameters():
    for name, case in cases().items():
        cls = FILTERS.load(name)
        assert dataset_ref.resolve(case.dataset).kind == "sim", (name, case.dataset)
        assert case.task in TASKS, (name, case.task)
        declared = {p.name for p in cls.PARAMS}
        assert set(case.params) <= declared, (name, set(case.params) - declared)
        assert case.first is None or case.first > 1, name


def test_groups_hold_every_builtin_filter_once_and_a_case_is_not_inherited():
    names = [f for *_, filters in groups() for f in filters]
    assert sorted(names) == sorted(FILTERS.builtin) and len(names) == len(set(names))
    assert len({group_id(g) for g in groups()}) == len(groups())

    class Sub(FILTERS.load("ukf")):  # a subclass is another filter: the parent's case is not its
        name = "sub"

    assert case_of(FILTERS.load("ukf")) == Case(params={"alpha": 0.8}) and case_of(Sub) is DEFAULT
    Sub.CASE = "sonar"
    with pytest.raises(TypeError, match="CASE: a replay.filters.case.Case"):
        case_of(Sub)


TOY = '''"""A toy built-in filter: the Kalman filter under another name (tests/test_builtin_cases.py)."""

from replay.filters.case import Case
from replay.filters.kalman import KalmanFilter


class ToyKF(KalmanFilter):
    name = "toy-kf"
    PARAMS = ()
    CASE = Case("sim/linear", "linear", {"q_scale": 2.0}, first=20)
'''


@pytest.mark.slow
def test_a_new_builtin_filter_is_one_file_plus_one_registry_line(tmp_path):
    """In a copy of the tree: filters/toy.py and one line in FILTERS; the suite's generated groups then
    run it (eval equals campaign, the rerun exact and a 1 % change refused), in plain Python."""
    copy = tmp_path / "tree"  # the installed layout: adapters/ and filters/ as replay.adapters, replay.filters
    skip = shutil.ignore_patterns("__pycache__", "*.pyc")
    for src, dst in (("replay", "replay"), ("adapters", "replay/adapters"), ("filters", "replay/filters"),
                     ("tests", "tests"), ("datasets", "datasets")):
        shutil.copytree(ROOT / src, copy / dst, ignore=skip)
    shutil.copy(ROOT / "pyproject.toml", copy)
    (copy / "replay" / "filters" / "toy.py").write_text(TOY)  # the one file
    init = copy / "replay" / "filters" / "__init__.py"
    text = init.read_text()
    line = '        "measurements": "replay.filters.measurements:Measurements",\n'
    assert text.count(line) == 1
    init.write_text(text.replace(line, line + '        "toy-kf": "replay.filters.toy:ToyKF",\n'))  # the one line
    env = {**os.environ, "PYTHONPATH": str(copy), "NUMBA_DISABLE_JIT": "1"}
    env.pop("PYTEST_XDIST_WORKER", None)
    probe = subprocess.run([sys.executable, "-c", "import replay.filters as f; print(f.__file__, 'toy-kf' in f.FILTERS)"],
                           cwd=copy, env=env, capture_output=True, text=True)
    assert probe.stdout.split() == [str(init), "True"], probe.stderr
    res = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "-p", "no:randomly",
                          "tests/test_pipeline.py", "tests/test_hostile_rerun.py", "tests/test_builtin_cases.py",
                          "-k", "(toy or cover or every_builtin_case or groups_hold) and not registry_line"],
                         cwd=copy, env=env, capture_output=True, text=True, timeout=1200)
    assert res.returncode == 0, res.stdout[-3000:] + res.stderr[-3000:]
    ran = re.findall(r"(\d+) passed", res.stdout)
    assert ran and int(ran[-1]) >= 6, res.stdout[-2000:]  # the toy's two generated groups, the coverage checks
    listed = subprocess.run([sys.executable, "-m", "pytest", "-q", "--collect-only", "-p", "no:cacheprovider",
                             "tests/test_pipeline.py", "tests/test_hostile_rerun.py", "-k", "toy"],
                            cwd=copy, env=env, capture_output=True, text=True)
    assert listed.stdout.count("linear:toy-kf") == 2, listed.stdout[-2000:]
