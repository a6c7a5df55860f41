"""The test sessions' kernel store: the compiled kernels kept from one pytest session to the next.

Each session runs with a fresh temporary ``REPLAY_CACHE_DIR`` (tests/conftest.py). Its
``kernels`` directory starts as a copy of the store and replaces the store when the session
ends (merged: a copy the session did not touch stays, one it compiled anew replaces the
store's older copy of the same model and template), so a second run does not compile again
what the first compiled; parallel workers (pytest-xdist) each merge theirs. The store holds the
product's kernel cache as the product writes it: copies named by the SHA-256 of their text,
checked against it before import, numba's files sealed and checked before they are read
(``filters/binding.py``, ``filters/kernel_files.py``); a changed kernel is a new name and a new
compilation. One store per checkout (keyed by its path): two checkouts of different versions
would otherwise prune each other's copies. Owner-only, like the product's cache; a store that
is not a private directory of this user is neither read nor replaced.
"""
from __future__ import annotations

import hashlib
import os
import shutil
import stat
import uuid
from pathlib import Path


def store_for(user_cache: Path, checkout: Path) -> Path:
    """``<user cache>/test-kernels/<hash of the checkout's path>``: beside, never inside, the
    developer's own ``kernels`` cache."""
    key = hashlib.sha256(str(checkout).encode()).hexdigest()[:16]
    return Path(user_cache) / "test-kernels" / key


def _private(path: Path) -> bool:
    try:
        st = os.stat(path, follow_symlinks=False)
    except OSError:
        return False
    return stat.S_ISDIR(st.st_mode) and st.st_uid == os.getuid() and not st.st_mode & 0o077


def restore(store: Path, kernels: Path) -> bool:
    """Copy the store into the session's (absent) ``kernels`` directory, file times kept (numba's
    index checks its source file's time and size). False, copying nothing, when there is no usable store."""
    if not _private(store):
        return False
    try:
        shutil.copytree(store, kernels, symlinks=True)
    except OSError:
        shutil.rmtree(kernels, ignore_errors=True)  # a half copy: the session compiles instead
        return False
    return True


def _superseded(store: Path, kernels: Path) -> set:
    """Names of the store's copies (``<prefix><model>_<digest>``) that the session has another
    digest of: the same model and template, older or newer sources (pruned, as the product does)."""
    mine = {p.stem.rsplit("_", 1)[0]: p.stem for p in kernels.glob("*.py")}
    return {p.stem for p in store.glob("*.py") if mine.get(p.stem.rsplit("_", 1)[0], p.stem) != p.stem}


def save(kernels: Path, store: Path) -> bool:
    """Merge the session's ``kernels`` directory into the store: the store's copies that the session
    did not replace (another worker's, another test selection's) and the session's, copied beside
    the store and renamed into place (a crash or a concurrent session leaves an old or a new
    store, never a mix)."""
    if not _private(kernels):
        return False
    parent = store.parent
    tag = f"{os.getpid()}.{uuid.uuid4().hex[:8]}"
    new, old = parent / f".new.{store.name}.{tag}", parent / f".old.{store.name}.{tag}"
    skip = shutil.ignore_patterns(".probe.*", "*.tmp.*")
    try:
        parent.mkdir(parents=True, exist_ok=True, mode=0o700)
        os.chmod(parent, 0o700)
        if _private(store):
            gone = _superseded(store, kernels)
            shutil.copytree(store, new, symlinks=True, ignore=lambda d, names: set(skip(d, names)) | {
                n for n in names if n.split(".", 1)[0] in gone or n.rsplit(".", 1)[0] in gone})
        shutil.copytree(kernels, new, symlinks=True, ignore=skip, dirs_exist_ok=True)
        os.chmod(new, 0o700)
        if store.exists() or store.is_symlink():
            os.rename(store, old)
        os.rename(new, store)
    except OSError:
        return False
    finally:
        shutil.rmtree(new, ignore_errors=True)
        shutil.rmtree(old, ignore_errors=True)
    return True
