"""The compiled loops take packed arguments (namedtuples of arrays, issue 37): their declared signatures
name each record's field types, so numba's cache keys a loop by them. A record whose fields change (another
layout, another class) is another key: looked up, it misses (the loop is compiled again), and an entry
written for it is never returned for the other. The typed fast call (``Kernel``) checks the fields too."""
from collections import namedtuple

import numba as nb
import numpy as np
from numba import types
from numba.core.caching import IndexDataCacheFile

from replay.filters import kalman_kernels, kalman_loops, pf_loop, rts_loops
from replay.filters.compiled.numba_internals import Kernel, _key
from replay.util import kernel_cache as kc

_S2, _S3 = types.float64[:, ::1], types.float64[:, :, ::1]


def _sealed(tmp_path):
    f = IndexDataCacheFile(str(tmp_path), "loop-1.py311", (1.0, 10))
    f.__class__ = kc.SealedCacheFile
    return f


def test_a_record_with_other_fields_is_another_cache_key(tmp_path):
    sig = kalman_loops.SIGMA_RUN
    obs = sig.args[4]
    assert isinstance(obs, types.NamedTuple) and obs.instance_class is kalman_loops.Obs
    assert [str(t) for t in obs.types] == ["array(float64, 3d, C)", "array(int64, 2d, C)",
                                           "array(float64, 3d, C)", "array(bool, 1d, C)"]
    # the same fields with R one matrix instead of a stack: another record type, another signature
    old = types.BaseTuple.from_types((_S3, types.int64[:, ::1], _S2, types.boolean[::1]), kalman_loops.Obs)
    stale = types.int64(*sig.args[:4], old, *sig.args[5:])
    assert stale != sig
    f = _sealed(tmp_path)
    f.save((stale, "cpu"), "code compiled for the old record")
    assert f.load((sig, "cpu")) is None  # a miss: the loop is compiled again
    f.save((sig, "cpu"), "code compiled for the new record")
    g = _sealed(tmp_path)  # another process: the sealed index read back, record types unpickled
    assert g.load((sig, "cpu")) == "code compiled for the new record"
    assert g.load((stale, "cpu")) == "code compiled for the old record"


def test_the_same_fields_in_another_record_class_are_another_key(tmp_path):
    fields = (_S3, types.int64[:, ::1], _S3, types.boolean[::1])
    Other = namedtuple("Obs", "Z sel R mask")  # same name and fields, not the loop's class
    a = types.BaseTuple.from_types(fields, kalman_loops.Obs)
    b = types.BaseTuple.from_types(fields, Other)
    assert a != b
    f = _sealed(tmp_path)
    f.save((types.int64(b), "cpu"), "code for another class")
    assert f.load((types.int64(a), "cpu")) is None


def test_every_loop_signature_declares_its_records_as_typeof_sees_them():
    """What the callers pass types exactly as declared (a declared Tuple where numba sees a UniTuple
    would never match, and the loop, compiled once with compilation then disabled, would refuse)."""
    M, steps, n, nz, p = 2, 3, 4, 2, 9
    obs = kalman_loops.Obs(np.zeros((M, steps, nz)), np.zeros((steps, 1 + nz), np.int64), np.zeros((1, nz, nz)),
                           np.zeros(nz, bool))
    par = kalman_loops.Params(np.zeros((steps, 1)), np.zeros((steps, 1)), np.zeros((1, n, n)))
    out = kalman_loops.Out(np.zeros((M, steps, n)), np.zeros((M, steps, n, n)), np.zeros((M, steps)))
    rule = kalman_kernels.Rule(np.zeros((p, n)), np.zeros(p), np.zeros(p))
    sig = kalman_loops.SIGMA_RUN.args
    assert [nb.typeof(v) for v in (obs, par, rule, out)] == [sig[4], sig[5], sig[6], sig[9]]
    assert nb.typeof(rule) == rts_loops.SIGMA_SMOOTH.args[5]
    N = 5
    pf = pf_loop.PF_RUN.args
    recs = (
        pf_loop.Cloud(np.zeros((N, n)), np.zeros(N), np.zeros(N)),
        pf_loop.Obs(np.zeros((steps, nz)), np.zeros((steps, 1 + nz), np.int64), np.zeros(nz, bool),
                    np.zeros(steps, np.int64), np.zeros(1, bool), np.zeros((1, nz, nz)), np.zeros((1, nz)), np.zeros(1)),
        pf_loop.Params(np.zeros((steps, 1)), np.zeros((steps, 1)), np.zeros((1, n)), np.zeros(n)),
        pf_loop.Proposal(True, np.zeros(nz, np.int64), np.zeros(nz), np.zeros((1, nz))),
        pf_loop.Resampling(1.0, 0.0, -1.0),
    )
    assert [nb.typeof(v) for v in recs] == list(pf[3:8])
    assert nb.typeof(pf_loop.Out(np.zeros((steps, n)), np.zeros((steps, n, n)), np.zeros(steps))) == pf[9]


Pair = namedtuple("Pair", "a b")


@nb.njit
def _first_plus_b(rec):
    return rec.a[0, 1] + rec.b[0]


def test_typed_fast_call_checks_the_fields_of_a_record():
    """Kernel calls numba's entry point directly while the arguments keep their types: a record whose
    field changed layout goes back through the dispatcher (never the entry point typed for C arrays)."""
    a = np.arange(6.0).reshape(2, 3)
    c, f = Pair(a, np.ones(2)), Pair(np.asfortranarray(a), np.ones(2))
    assert _key((c,)) != _key((f,)) and _key((c,)) == _key((Pair(a.copy(), np.zeros(2)),))
    k = Kernel(_first_plus_b)
    assert k(c) == 2.0
    assert k(f) == 2.0 and k(Pair(a[:, ::-1], np.ones(2))) == 2.0  # a[0, 1] of the reversed: 1 + 1
    assert len(_first_plus_b.signatures) == 3
