"""The kernel cache (filters/compiled/copies.py, here with paper 002's template): a cached copy is imported only when
its content hashes to its name, and old copies of a model are pruned with their numba caches.

These tests never compile a kernel: the copy is imported (numba compiles on first call).
"""
from __future__ import annotations

import hashlib
import sys

import numpy as np
import pytest

from replay.filters.compiled import copies, files
from replay.filters.p002 import stcpf
from replay.models.random_walk import RandomWalkPosition
from replay.util import kernel_cache as kc

PREFIX = "replay_compiled_"
MODEL = PREFIX + "0badcafe_"


@pytest.fixture
def cache(tmp_path, monkeypatch):
    """An empty kernel cache; the process's copies and counts restored afterwards."""
    monkeypatch.setenv("REPLAY_CACHE_DIR", str(tmp_path))
    monkeypatch.setattr(copies, "_bound", {})
    report = {"rewritten": 0, "pruned": 0, "damaged": 0}
    monkeypatch.setattr(files, "CACHE_REPORT", report)
    monkeypatch.setattr(kc, "CACHE_REPORT", report)
    before = set(sys.modules)
    yield tmp_path / "kernels"
    for name in set(sys.modules) - before:
        if name.startswith(PREFIX):
            del sys.modules[name]


def _name(text: str, model: str = MODEL) -> str:
    return model + hashlib.sha256(text.encode()).hexdigest()[:20]


def _numba_files(d, name):
    """Stand-ins for numba's index and machine code of copy ``name``."""
    (d / "__pycache__").mkdir(parents=True, exist_ok=True)
    files = [d / "__pycache__" / f"{name}.step-12.py311.nbi", d / "__pycache__" / f"{name}.step-12.py311.1.nbc"]
    for f in files:
        f.write_bytes(b"machine code")
    return files


def test_tampered_copy_is_rewritten_and_its_numba_cache_dropped(cache):
    text = "VALUE = 1\n"
    name = _name(text)
    cache.mkdir(parents=True)
    (cache / f"{name}.py").write_text("VALUE = 666\n")  # same name, other content
    stale = _numba_files(cache, name)
    mod = copies.load(name, text)
    assert mod.VALUE == 1 and (cache / f"{name}.py").read_text() == text
    assert files.CACHE_REPORT == {"rewritten": 1, "pruned": 0, "damaged": 0}
    assert not any(f.exists() for f in stale)
    copies.load(name, text)  # intact now: imported as it is
    assert files.CACHE_REPORT["rewritten"] == 1


def test_truncated_copy_is_rewritten(cache):
    text = "VALUE = 2\nOTHER = 3\n"
    name = _name(text)
    cache.mkdir(parents=True)
    (cache / f"{name}.py").write_text(text[:9])
    assert copies.load(name, text).OTHER == 3
    assert files.CACHE_REPORT["rewritten"] == 1


def test_old_copies_of_the_model_are_pruned_others_kept(cache):
    cache.mkdir(parents=True)
    old = _name("VALUE = 0\n")
    other_model = _name("VALUE = 0\n", "replay_compiled_12345678_")
    for n in (old, other_model):
        (cache / f"{n}.py").write_text("VALUE = 0\n")
    old_cache = _numba_files(cache, old)
    kept_cache = _numba_files(cache, other_model)
    text = "VALUE = 5\n"
    assert copies.load(_name(text), text).VALUE == 5
    assert sorted(p.name for p in cache.glob("*.py")) == sorted([f"{_name(text)}.py", f"{other_model}.py"])
    assert not any(f.exists() for f in old_cache) and all(f.exists() for f in kept_cache)
    assert files.CACHE_REPORT == {"rewritten": 0, "pruned": 1, "damaged": 0}


def test_bound_model_copy_is_verified_before_import(cache):
    """bind() names the copy by model and content; an edited copy is replaced before import."""
    m = RandomWalkPosition(np.eye(2), np.eye(2))
    first = stcpf.bound_kernels(m.kernels())
    path = cache / f"{first.__name__}.py"
    text = path.read_text()
    assert first.__name__.startswith(PREFIX) and hashlib.sha256(text.encode()).hexdigest()[:20] == \
        first.__name__.rsplit("_", 1)[1]
    path.write_text("import os  # injected\n" + text)
    copies._bound.clear()
    again = stcpf.bound_kernels(m.kernels())
    assert again.__name__ == first.__name__ and path.read_text() == text
    assert files.CACHE_REPORT["rewritten"] == 1
