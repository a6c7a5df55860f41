"""A cached loop is never run against an edited callee: the sealed index holds the digest of every
source of compiled code (sources_digest in replay.util.kernel_cache), not only its function's file's stamp."""
from replay.util import kernel_cache as kc


def _file(tmp_path):
    return kc.SealedCacheFile(cache_path=str(tmp_path), filename_base="f-1.py311", source_stamp=(1.0, 10))


def test_an_index_written_before_a_callee_changed_is_not_used(tmp_path, monkeypatch):
    monkeypatch.setattr(kc, "sources_digest", lambda: "a")
    _file(tmp_path).save(("sig",), "code compiled against callee a")
    assert _file(tmp_path).load(("sig",)) == "code compiled against callee a"
    monkeypatch.setattr(kc, "sources_digest", lambda: "b")  # e.g. kalman_kernels.py edited
    assert _file(tmp_path).load(("sig",)) is None


def test_the_digest_covers_the_kernels_a_loop_calls():
    names = {n for n, _ in kc.source_files()}
    assert {"filters/kalman_kernels.py", "filters/kalman_loops.py", "filters/compiled/rows.py",
            "replay/models/kinematic2_kernels.py", "replay/util/kernels.py", "replay/model.py"} <= names
    assert not any(n.startswith("replay/cli") for n in names)
    assert len(kc.sources_digest()) == 64
