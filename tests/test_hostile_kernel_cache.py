"""A damaged or hostile kernel cache (``$REPLAY_CACHE_DIR/kernels``; corpus: tests/hostile.py).

numba's cache files of a bound copy (``.nbi`` index, ``.nbc`` machine code: pickles) are sealed
with an HMAC under this user's key (replay.util.kernel_cache): a damaged one is never unpickled, it is
removed, counted and compiled again, and the numbers are those of the undamaged cache. A cache
directory that cannot be used compiles in memory with one note. Each test has its own
``REPLAY_CACHE_DIR``; the small random-walk model's rows kernels compile in about a second.
"""
from __future__ import annotations

import os
import pickle
import stat
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from hostile import register

from replay.filters.compiled import copies, files, loops, numba_internals, rows
from replay.models.random_walk import RandomWalkPosition
from replay.util import kernel_cache as kc

register("kcache-nbc-random-bytes", "kcache-nbi-reduce-pickle", "kcache-nbi-truncated", "kcache-unsealed-plain-numba",
         "kcache-dir-open-to-others", "kcache-dir-is-a-file", "kcache-dir-read-only", "kcache-cli-dir-is-a-file",
         "kcache-cli-stcpf-damaged", "kcache-fetch-dir-is-a-file",
         "kcache-nbc-damaged-after-import", "kcache-full-disk",
         "kcache-dir-of-another-user")

MODEL = RandomWalkPosition(np.eye(2), np.diag([1.0, 2.0]))
X = np.arange(6.0).reshape(3, 2)


@pytest.fixture
def cache(tmp_path, monkeypatch):
    """An empty kernel cache of this test; the process's copies and counts restored afterwards."""
    monkeypatch.setenv("REPLAY_CACHE_DIR", str(tmp_path / "cache"))
    report = {"rewritten": 0, "pruned": 0, "damaged": 0}
    monkeypatch.setattr(files, "CACHE_REPORT", report)
    monkeypatch.setattr(kc, "CACHE_REPORT", report)
    monkeypatch.setattr(loops, "_rows", {})
    monkeypatch.setattr(copies, "_bound", {})
    before = set(sys.modules)
    yield tmp_path / "cache" / "kernels"
    for name in set(sys.modules) - before:
        if name.startswith("replay_rows_"):
            del sys.modules[name]


def _copy():
    """The rows copy of the random-walk model, imported afresh (a new process would do the same)."""
    copies._bound.clear()
    return copies.bind(rows, MODEL.kernels(), "rows kernels")


def _f_rows(mod):
    """f_rows of the copy over X, and whether it came from numba's disk cache."""
    out = np.zeros_like(X)
    mod.f_rows(X, np.zeros(0), out)
    return out, sum(mod.f_rows.stats.cache_hits.values())


def _files(cache, suffix):
    return sorted((cache / "__pycache__").glob(f"replay_rows_*{suffix}"))


def test_random_bytes_over_nbc_detected_removed_counted_same_numbers(cache, caplog):
    want, hits = _f_rows(_copy())
    assert hits == 0 and _files(cache, ".nbc")
    again, hits = _f_rows(_copy())
    assert hits == 1 and np.array_equal(again, want)  # sealed files are read back: no recompilation
    for f in _files(cache, ".nbc"):
        f.write_bytes(os.urandom(4000))
    got, hits = _f_rows(_copy())
    assert hits == 0 and np.array_equal(got, want)
    assert files.CACHE_REPORT["damaged"] == 1
    assert "kernel cache: 1 damaged file of random_walk removed and compiled again" in caplog.text
    assert all(kc.unseal(f.read_bytes()) is not None for f in _files(cache, ".nb?"))  # sealed anew
    assert _f_rows(_copy())[1] == 1 and files.CACHE_REPORT["damaged"] == 1


def test_nbi_pickle_that_runs_code_is_never_unpickled(cache, tmp_path):
    want, _ = _f_rows(_copy())
    marker = tmp_path / "ran"

    class Hostile:
        def __reduce__(self):
            return (open, (str(marker), "w"))

    for f in _files(cache, ".nbi"):
        f.write_bytes(pickle.dumps(Hostile()))
    got, hits = _f_rows(_copy())
    assert not marker.exists()
    assert hits == 0 and np.array_equal(got, want) and files.CACHE_REPORT["damaged"] == 1


def test_damage_after_the_import_is_caught_when_the_function_is_first_called(cache, caplog):
    """Files damaged between the copy's import (checked then) and its first call (another process,
    a bad disk): the check at unpickling catches them too."""
    want, _ = _f_rows(_copy())
    mod = _copy()
    assert files.CACHE_REPORT["damaged"] == 0
    for f in _files(cache, ".nbc"):
        f.write_bytes(b"\x80\x04garbage")
    got, hits = _f_rows(mod)
    assert hits == 0 and np.array_equal(got, want) and files.CACHE_REPORT["damaged"] == 1
    assert "1 damaged file of random_walk removed" in caplog.text


def test_full_disk_means_not_cached_not_an_error(cache, monkeypatch, caplog):
    def full(*_a, **_k):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(kc, "_noted", set())
    mod = _copy()  # the copy's text written; numba's files next, on a full disk
    monkeypatch.setattr(kc, "write_private", full)
    monkeypatch.setattr(copies, "write_private", full)
    out, hits = _f_rows(mod)
    assert hits == 0 and np.array_equal(out, X) and not _files(cache, ".nb?")
    assert caplog.text.count("cannot write (No space left on device); compiled code not cached") == 1
    mod2 = _copy()  # and the copy itself cannot be written: compiled in memory
    (cache / f"{mod2.__name__}.py").unlink()
    del sys.modules[mod2.__name__]
    mod3 = _copy()
    assert not mod3.CACHED and np.array_equal(_f_rows(mod3)[0], X)
    assert "kernels compiled in memory for this process" in caplog.text


def test_truncated_index_and_unsealed_plain_numba_files_are_recompiled(cache):
    want, _ = _f_rows(_copy())
    nbi = _files(cache, ".nbi")[0]
    nbi.write_bytes(nbi.read_bytes()[:200])
    assert np.array_equal(_f_rows(_copy())[0], want) and files.CACHE_REPORT["damaged"] == 1
    # a file as plain numba writes it (no seal) is not read either
    nbc = _files(cache, ".nbc")[0]
    nbc.write_bytes(kc.unseal(nbc.read_bytes()))
    got, hits = _f_rows(_copy())
    assert hits == 0 and np.array_equal(got, want) and files.CACHE_REPORT["damaged"] == 2


def test_plain_numba_reading_a_sealed_index_sees_another_version():
    """The seal is a pickled string numba takes for another version's stamp: it recompiles, it never
    unpickles the rest (nor fails) should some numba cache of a copy not be sealed."""
    from numba.core.caching import IndexDataCacheFile

    raw = kc.seal(pickle.dumps("0.0") + pickle.dumps(("stamp", {"key": "x.1.nbc"})))
    assert kc.unseal(raw) is not None
    assert kc.unseal(raw[:-1] + b"!") is None and kc.unseal(raw[:50]) is None
    plain = IndexDataCacheFile("/nonexistent", "x", "stamp")
    f = __import__("io").BytesIO(raw)
    assert pickle.load(f) != plain._version  # the version check numba makes first


def test_rows_cfuncs_are_sealed_and_checked(cache):
    """loops.row_kernels' cfuncs share the copy's numba cache: written sealed, damage counted."""
    a = loops.row_kernels(MODEL, (0, 1))
    found = _files(cache, ".nb?")
    assert found and all(kc.unseal(f.read_bytes()) is not None for f in found)
    nbc = _files(cache, ".nbc")
    assert len(nbc) == 2  # f_rows, h_rows
    for f in nbc:
        f.write_bytes(os.urandom(100))
    loops._rows.clear()
    copies._bound.clear()
    b = loops.row_kernels(MODEL, (0, 1))
    assert files.CACHE_REPORT["damaged"] == 2
    assert [x._cache_hits for x in b] == [0, 0] and all(x.address for x in a + b)


def test_cache_directory_is_owner_only(cache):
    _f_rows(_copy())
    for d in (cache, cache / "__pycache__"):
        assert stat.S_IMODE(d.stat().st_mode) == 0o700
    written = list(cache.glob("*.py")) + _files(cache, ".nb?")
    assert written and all(stat.S_IMODE(f.stat().st_mode) == 0o600 for f in written)
    cache.chmod(0o777)
    (cache / "__pycache__").chmod(0o775)
    _files(cache, ".nbc")[0].chmod(0o666)
    _copy()
    assert stat.S_IMODE(cache.stat().st_mode) == stat.S_IMODE((cache / "__pycache__").stat().st_mode) == 0o700
    assert stat.S_IMODE(_files(cache, ".nbc")[0].stat().st_mode) == 0o600


@pytest.mark.skipif(not hasattr(os, "getuid") or os.getuid() != 0, reason="needs root to give a directory away")
def test_cache_dir_of_another_user_is_not_used(cache, monkeypatch, caplog):
    monkeypatch.setattr(kc, "_noted", set())
    cache.mkdir(parents=True, mode=0o700)
    os.chown(cache, 65534, 65534)
    mod = _copy()
    assert not mod.CACHED and np.array_equal(_f_rows(mod)[0], X) and not list(cache.iterdir())
    assert f"REPLAY_CACHE_DIR={cache.parent}: {cache} belongs to another user; kernels compiled in memory" in caplog.text


@pytest.mark.parametrize("where", ["file", "read-only"])
def test_unusable_cache_dir_compiles_in_memory_with_one_note(where, tmp_path, monkeypatch, caplog):
    if where == "file":
        root = tmp_path / "cache"
        root.write_text("not a directory\n")
    else:
        root = Path("/sys/fs")  # no directory can be made there (root ignores permission bits)
        try:
            (root / "kernels").mkdir()
        except OSError:
            pass
        else:
            (root / "kernels").rmdir()
            pytest.skip("/sys/fs is writable here")
    monkeypatch.setenv("REPLAY_CACHE_DIR", str(root))
    monkeypatch.setattr(kc, "_noted", set())
    # the process's row kernels compiled by earlier tests (cached on disk then) are not what is tested
    monkeypatch.setattr(loops, "_rows", {})
    monkeypatch.setattr(copies, "_bound", {})
    mod = _copy()
    try:
        out, hits = _f_rows(mod)
        assert hits == 0 and np.array_equal(out, X)  # the random walk's f: the identity
        assert type(mod.f_rows._cache).__name__ == "NullCache"
        cf = loops.row_kernels(RandomWalkPosition(np.eye(2), np.eye(2)), (0,))[0]
        assert cf.address and type(cf._cache).__name__ == "NullCache"
    finally:
        del sys.modules[mod.__name__]
        loops._rows.clear()
        copies._bound.clear()
    notes = [r.getMessage() for r in caplog.records if "REPLAY_CACHE_DIR" in r.getMessage()]
    assert len(notes) == 1 and notes[0].startswith(f"REPLAY_CACHE_DIR={root}: ")
    assert "compiled in memory" in notes[0]
    if where == "file":
        assert root.read_text() == "not a directory\n"


def _eval(env, out):
    cmd = [sys.executable, "-m", "replay.cli", "eval", "sim/ungm", "-f", "stcpf", "-n", "2", "--first", "30",
           "--out", str(out)]
    return subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=600)


@pytest.mark.slow
def test_cli_stcpf_with_cache_dir_a_file_runs_with_one_note(tmp_path):
    root = tmp_path / "cache"
    root.write_text("x")
    res = _eval(dict(os.environ, REPLAY_CACHE_DIR=str(root)), tmp_path / "o")
    assert res.returncode == 0, res.stderr
    assert "Traceback" not in res.stderr
    notes = [ln for ln in res.stderr.splitlines() if "REPLAY_CACHE_DIR" in ln]
    assert len(notes) == 1 and f"REPLAY_CACHE_DIR={root}: not a directory" in notes[0]


@pytest.mark.slow
def test_cli_stcpf_damaged_cache_gives_the_undamaged_numbers(tmp_path):
    """The issue's case: the .nbc files overwritten with random bytes made stcpf 'diverged 2/2' forever."""
    env = dict(os.environ, REPLAY_CACHE_DIR=str(tmp_path / "cache"))
    first = _eval(env, tmp_path / "a")
    assert first.returncode == 0, first.stderr
    nbc = sorted((tmp_path / "cache" / "kernels" / "__pycache__").glob("*.nbc"))
    assert nbc
    for f in nbc:
        f.write_bytes(os.urandom(5000))
    again = _eval(env, tmp_path / "b")
    assert again.returncode == 0, again.stderr
    assert f"kernel cache: {len(nbc)} damaged files of ungm removed and compiled again" in again.stderr
    est = "estimates/stcpf.csv.gz"
    assert (tmp_path / "a" / est).read_bytes() == (tmp_path / "b" / est).read_bytes()
    a, b = (pd.read_csv(tmp_path / d / "leaderboard.csv").drop(columns="us_per_step") for d in "ab")
    assert b["diverged"].tolist() == [0] and b["pos_rmse"].tolist()[0] > 0
    pd.testing.assert_frame_equal(a, b)


def test_fetch_into_a_cache_dir_that_is_a_file_names_the_variable(tmp_path):
    from hostile import assert_refused

    root = tmp_path / "cache"
    root.write_text("x")
    env = {"REPLAY_CACHE_DIR": str(root), "REPLAY_DATASET_BASE_URL": "http://127.0.0.1:9"}  # refused before any request
    line = assert_refused(["datasets", "fetch", "bohai/20220822_0_6"], r"from REPLAY_CACHE_DIR\)", env=env)
    assert "is a file, not a directory" in line and root.read_text() == "x"


# ------------------------------------------------------------------ issue 33: the seal is keyed, numba's own files too

register("kcache-forged-sha256-reseal", "kcache-forged-other-key", "kcache-key-file-checks",
         "kcache-data-of-another-signature", "kcache-model-kernels-sealed")


def _hostile_payload(marker):
    class Hostile:
        def __reduce__(self):
            return (open, (str(marker), "w"))

    return pickle.dumps(Hostile())


@pytest.mark.parametrize("forge", ["sha256", "other-key"])
def test_forged_reseal_of_a_pickle_is_never_executed(cache, tmp_path, forge):
    """Anyone who can write the cache but not read the key (the old unkeyed SHA-256 seal, or a
    well-formed HMAC under another key) gets nothing unpickled: removed, compiled again, same numbers."""
    import hashlib

    want, _ = _f_rows(_copy())
    marker = tmp_path / "ran"
    payload = _hostile_payload(marker)
    if forge == "sha256":
        sealed = pickle.dumps("replay-sha256:" + hashlib.sha256(payload).hexdigest(), protocol=4) + payload
    else:
        sealed = kc.seal(payload, key=os.urandom(kc.KEY_BYTES))
    for f in _files(cache, ".nb?"):
        f.write_bytes(sealed)
    got, hits = _f_rows(_copy())
    assert not marker.exists()
    assert hits == 0 and np.array_equal(got, want) and files.CACHE_REPORT["damaged"] >= 1
    assert all(kc.unseal(f.read_bytes()) is not None for f in _files(cache, ".nb?"))  # resealed, ours


def test_key_file_created_owner_only_and_refused_where_it_cannot_be_trusted(tmp_path, monkeypatch, caplog):
    monkeypatch.setattr(kc, "_keys", {})
    monkeypatch.setattr(kc, "_noted", set())
    monkeypatch.setenv("REPLAY_CACHE_DIR", str(tmp_path / "cache"))
    key = tmp_path / "config" / "replay" / "cache-key"
    monkeypatch.setenv("REPLAY_CACHE_KEY", str(key))
    k = kc.cache_key()
    assert k == key.read_bytes() and len(k) == 32 and stat.S_IMODE(key.stat().st_mode) == 0o600
    assert kc.unseal(kc.seal(b"x")) == b"x"
    key.chmod(0o644)  # readable by others: not a secret
    monkeypatch.setattr(kc, "_keys", {})
    assert kc.cache_key() is None and "readable or writable by others" in caplog.text
    assert kc.unseal(kc.seal(b"x", key=k)) is None  # nothing trusted without the key
    inside = tmp_path / "cache" / "key"  # inside the cache it seals: refused
    monkeypatch.setenv("REPLAY_CACHE_KEY", str(inside))
    assert kc.cache_key() is None and "inside the cache directory" in caplog.text


def test_data_file_of_another_signature_is_not_executed(tmp_path):
    """An index naming a data file that holds another signature's code (what concurrent cold starts
    left with numba's own save): not returned, counted; the entry is written again on save."""
    from numba.core.caching import IndexDataCacheFile

    f = IndexDataCacheFile(str(tmp_path), "f-1.py311", (1.0, 10))
    f.__class__ = kc.SealedCacheFile
    f.save(("sig-a",), "code of a")
    f.save(("sig-b",), "code of b")
    assert f.load(("sig-a",)) == "code of a" and f.load(("sig-b",)) == "code of b"
    index = f._load_index()
    a, b = tmp_path / index[("sig-a",)], tmp_path / index[("sig-b",)]
    a.write_bytes(b.read_bytes())  # a's file now holds b's (sealed) code
    before = kc.CACHE_REPORT["damaged"]
    assert f.load(("sig-a",)) is None and kc.CACHE_REPORT["damaged"] == before + 1
    f.save(("sig-a",), "code of a")
    assert f.load(("sig-a",)) == "code of a" and f.load(("sig-b",)) == "code of b"


@pytest.mark.slow
def test_model_kernels_own_numba_cache_is_sealed_and_damage_rebuilt(tmp_path):
    """numba's cache of the library's kernels (beside the package, here NUMBA_CACHE_DIR): sealed; a
    damaged file is removed and rebuilt in the next process, which gives the same numbers.
    Slow: each process compiles the kernels into a fresh NUMBA_CACHE_DIR (15-20 s); the fast subset
    keeps test_random_bytes_over_nbc_detected_removed_counted_same_numbers and
    test_truncated_index_and_unsealed_plain_numba_files_are_recompiled (damage detected, removed, the
    same numbers)."""
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "numba")}
    code = ("import numpy as np; from replay.models.random_walk import RandomWalkPosition as M; "
            "m = M(np.eye(2), np.diag([1.0, 2.0])); print(repr(m.f(np.arange(6.0).reshape(3, 2), 0).tolist()))")
    run = lambda: subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True)  # noqa: E731
    first = run()
    assert first.returncode == 0, first.stderr
    written = sorted((tmp_path / "numba").rglob("random_walk_kernels*.nb[ic]"))
    assert written and all(kc.unseal(p.read_bytes()) is not None for p in written)
    for p in written:
        if p.suffix == ".nbc":
            p.write_bytes(os.urandom(300))
    again = run()
    assert again.returncode == 0 and again.stdout == first.stdout
    assert "damaged file" in again.stderr and "random_walk" in again.stderr
    assert all(kc.unseal(p.read_bytes()) is not None for p in (tmp_path / "numba").rglob("*.nb[ic]"))


GUFUNC = '''
import sys
import numpy as np, numba as nb
from replay.util import kernel_cache  # noqa: F401
if sys.argv[1] == "shift":  # compile something first: this process's function counter moves on
    nb.njit(lambda x: x + 1)(1)
def k(x, p, out):
    for i in range(x.shape[0]):
        out[i] = 2.0 * x[i] + p[0]
g = nb.guvectorize(["void(f8[:], f8[:], f8[:])"], "(n),(p),(n)", cache=True)(k)
out = np.empty((2, 3))
g(np.arange(6.0).reshape(2, 3), np.array([1.0]), out)
print(out.tolist())
'''


@pytest.mark.slow
def test_gufunc_loop_cached_beside_another_compilation_of_its_kernel_is_built_again(tmp_path):
    """The crash of issue 33: a gufunc's loop cached by one process beside its kernel compiled by another
    (the kernel's cache entry gone, or written by a concurrent process) names a function this process
    does not have; numba's own cache then calls a null pointer (segfault). Built again here: the numbers.
    Slow: three processes compile the gufunc into fresh caches (15-20 s); the fast subset keeps
    test_truncated_index_and_unsealed_plain_numba_files_are_recompiled and
    test_data_file_of_another_signature_is_not_executed (a cache entry this process cannot use is
    compiled again, never run)."""
    (tmp_path / "gk.py").write_text(GUFUNC)
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "numba"), "PYTHONPATH": str(tmp_path)}
    run = lambda how: subprocess.run([sys.executable, str(tmp_path / "gk.py"), how], env=env,  # noqa: E731
                                     capture_output=True, text=True, timeout=300)
    first = run("plain")
    assert first.returncode == 0 and first.stdout.strip() == "[[1.0, 3.0, 5.0], [7.0, 9.0, 11.0]]", first.stderr
    kernel_index = [p for p in (tmp_path / "numba").rglob("gk.k-*.nbi")]
    assert len(kernel_index) == 1 and list((tmp_path / "numba").rglob("guf-gk.k-*.nbi"))
    kernel_index[0].unlink()  # the kernel is compiled again, the loop is loaded from the cache
    again = run("shift")
    assert again.returncode == 0, f"exit {again.returncode}: {again.stderr[-500:]}"
    assert again.stdout == first.stdout and "a loop of another compilation" in again.stderr
    assert run("plain").stdout == first.stdout  # and the entry it rewrote serves the next process
