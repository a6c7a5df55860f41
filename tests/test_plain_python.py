"""NUMBA_DISABLE_JIT=1: a whole `replay eval` runs as plain Python and gives the compiled numbers.

The same command twice in subprocesses (numba reads the variable at import), once with numba's
JIT disabled (every kernel, bound copy, cfunc and whole-run loop falls back to its Python
function: docs/architecture.md, "How a compiled step is called") and once compiled. Kalman
filters' metrics agree to 1e-12 relative, the PF's bit for bit (same draws from the same
generator, same arithmetic; the kernels call the C library's functions in both modes).
"""
from __future__ import annotations

import json
import math
import os
import subprocess
import sys

import pytest

FILTERS = ("ekf", "ukf", "ckf", "pf", "ekf+rts", "ukf+rts", "ckf+rts")
SCORES = ("pos_rmse", "x_rmse", "y_rmse", "z_rmse", "pitch_rmse", "yaw_rmse", "ate", "final_err", "nees")


def _eval(out, plain: bool) -> dict:
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_DISABLE_JIT"}
    if plain:
        env["NUMBA_DISABLE_JIT"] = "1"
    cmd = [sys.executable, "-m", "replay.cli", "eval", "sim/auv-sonar", "--filters", ",".join(FILTERS),
           "--runs", "2", "--dataset-param", "steps=30", "-q", "-o", str(out)]
    res = subprocess.run(cmd, capture_output=True, text=True, env=env, timeout=600)
    assert res.returncode == 0, res.stderr
    assert "failed" not in res.stderr, res.stderr  # a filter whose runs fail is only a warning
    return json.loads((out / "manifest.json").read_text())["results"]


@pytest.mark.slow  # two evaluations in fresh processes: ~4 s (numba's start-up, cached kernels)
def test_plain_python_equals_compiled(tmp_path):
    plain, compiled = _eval(tmp_path / "plain", True), _eval(tmp_path / "compiled", False)
    for name in FILTERS:
        p, c = plain[name], compiled[name]
        assert (p["runs"], p["failed"], p["diverged"]) == (c["runs"], c["failed"], c["diverged"]) == (2, 0, 0), name
        assert all(math.isfinite(c[k]) for k in SCORES), name
        if name == "pf":  # every number, bit for bit (timing aside)
            _assert_same(p, c)
        else:
            for k in SCORES:
                assert p[k] == pytest.approx(c[k], rel=1e-12, abs=0), (name, k)


def _assert_same(p: dict, c: dict) -> None:
    """Equal key for key, NaN equal to NaN (timing aside)."""
    assert p.keys() == c.keys()
    for k in p:
        if k == "us_per_step":
            continue
        a, b = p[k], c[k]
        same = a == b or (isinstance(a, float) and isinstance(b, float) and math.isnan(a) and math.isnan(b))
        assert same, (k, a, b)


def plain_kernel(x, p, out):  # a module-level Python function, not a numba one
    out[0] = x[0]


def test_plain_kernel_refused_when_compiling():
    """Only with numba's JIT disabled may a kernel be a plain Python function: compiled, it is refused
    with one line (not a numba typing error deep in a bound copy)."""
    from numba.core import config

    from replay.filters.compiled import copies
    from replay.util.errors import ReplayError

    assert not config.DISABLE_JIT
    with pytest.raises(ReplayError, match="plain_kernel.* is not a module-level numba function"):
        copies.where(plain_kernel)
