"""The test sessions' kernel store (tests/kernel_store.py): kept per checkout, copied in with the
files' times (numba's index checks them), replaced whole at the end, never read when it is not a
private directory of this user."""
import os

import kernel_store


def _kernels(root, files):
    d = root / "kernels"
    (d / "__pycache__").mkdir(parents=True, mode=0o700)
    os.chmod(d, 0o700)
    for name, text in files.items():
        (d / name).write_text(text)
    return d


def test_store_is_per_checkout_beside_the_user_kernel_cache(tmp_path):
    a = kernel_store.store_for(tmp_path, tmp_path / "wt" / "a")
    assert a.parent == tmp_path / "test-kernels" and a != kernel_store.store_for(tmp_path, tmp_path / "wt" / "b")
    assert a == kernel_store.store_for(tmp_path, tmp_path / "wt" / "a")


def test_saved_then_restored_with_times_and_replaced_whole(tmp_path):
    store = tmp_path / "cache" / "test-kernels" / "k"
    first = _kernels(tmp_path / "s1", {"replay_rows_a_1.py": "x = 1\n", "__pycache__/replay_rows_a_1.f-1.nbi": "i"})
    os.utime(first / "replay_rows_a_1.py", (1_000_000, 1_000_000))
    assert kernel_store.save(first, store)
    assert oct(store.stat().st_mode & 0o777) == "0o700"
    again = tmp_path / "s2" / "kernels"
    assert kernel_store.restore(store, again)
    assert (again / "replay_rows_a_1.py").read_text() == "x = 1\n"
    assert (again / "replay_rows_a_1.py").stat().st_mtime == 1_000_000  # numba's index stays valid
    assert (again / "__pycache__" / "replay_rows_a_1.f-1.nbi").read_text() == "i"
    # the next session pruned the old copy and compiled a new one: it replaces the store's, with
    # numba's files of the old one; a copy of another model that session did not use stays
    (again / "replay_rows_a_1.py").unlink()
    (again / "__pycache__" / "replay_rows_a_1.f-1.nbi").unlink()
    (again / "replay_rows_a_2.py").write_text("x = 2\n")
    (again / "__pycache__" / "replay_rows_a_2.f-1.nbi").write_text("j")
    other = _kernels(tmp_path / "s3", {"replay_rows_b_7.py": "y = 7\n", "__pycache__/replay_rows_b_7.f-1.nbi": "k"})
    assert kernel_store.save(other, store)
    assert kernel_store.save(again, store)
    assert sorted(p.name for p in store.iterdir()) == ["__pycache__", "replay_rows_a_2.py", "replay_rows_b_7.py"]
    assert sorted(p.name for p in (store / "__pycache__").iterdir()) == ["replay_rows_a_2.f-1.nbi",
                                                                         "replay_rows_b_7.f-1.nbi"]
    assert not [p for p in store.parent.iterdir() if p.name.startswith(".")]  # no temporary left


def test_store_open_to_others_or_absent_is_not_read(tmp_path):
    store = tmp_path / "store"
    assert not kernel_store.restore(store, tmp_path / "k1") and not (tmp_path / "k1").exists()
    store.mkdir(mode=0o700)
    (store / "replay_rows_a_1.py").write_text("x = 1\n")
    os.chmod(store, 0o777)
    assert not kernel_store.restore(store, tmp_path / "k2") and not (tmp_path / "k2").exists()
    link = tmp_path / "link"
    link.symlink_to(store)
    os.chmod(store, 0o700)
    assert not kernel_store.restore(link, tmp_path / "k3")
    assert kernel_store.restore(store, tmp_path / "k4")


def test_session_without_kernels_leaves_the_store(tmp_path):
    store = tmp_path / "store"
    store.mkdir(mode=0o700)
    (store / "keep.py").write_text("")
    assert not kernel_store.save(tmp_path / "none", store)
    assert (store / "keep.py").exists()
