"""Where exports (MCAP files, ROS 2 bag directories) may go, and how they replace an old one.

* **Never onto an input.** An export target may not equal, contain or lie inside what
  the export reads: the run directory, the dataset (CSV, MCAP, bag file or bag
  directory), the topic mapping (:func:`run_inputs`, :func:`dataset_inputs`), nor
  the other export target of the same command.
* **Only our own outputs are replaced.** An existing MCAP is replaced only when its
  Header record names ``replay`` as the writing library; an existing directory only
  when it is empty or a ROS 2 bag whose ``metadata.yaml`` carries :data:`MARK_KEY`
  in ``custom_data`` (written by :func:`staged_bag`). Anything else is refused in one
  line.
* **Old or new, never a mix.** A file is written to ``.<name>.replay-tmp-<pid>``
  beside the target, fsynced and renamed over it (:func:`staged_file`); a bag
  directory is written inside such a hidden directory and swapped in with one
  ``renameat2(RENAME_EXCHANGE)`` (or, where the kernel or file system lacks it, two
  renames: a kill between them leaves no bag and the old one in the hidden
  directory). A killed export leaves the old output (or none) and at most one hidden
  temporary, which the next export to the same target removes once its process is
  gone (:func:`clean_stale`).
"""

from __future__ import annotations

import glob
import json
import os
import shutil
import struct
from contextlib import contextmanager
from pathlib import Path

from replay.util.errors import DataError, ReplayError
from replay.util.files import check_writable, refuse_overlap
from replay.util.staging import alive
from replay.util.staging import exchange  # noqa: F401 (exchange: re-exported)

MARK_KEY = "replay.output"  # custom_data key of the ROS 2 bags written through staged_bag
MCAP_LIBRARY = "replay"  # the Header library string of the MCAP files replay writes
_TMP = ".replay-tmp-"


# ---------------------------------------------------------------- what an export reads


def dataset_inputs(dataset, mapping=None, data_dir=None) -> list[Path]:
    """The files a dataset id or path is read from (none for a simulator), and the mapping."""
    from replay.data import dataset_ref

    found = [Path(mapping)] if mapping else []
    try:
        path = dataset_ref.resolve(dataset).locate(data_dir) if isinstance(dataset, (str, Path)) else None
    except (OSError, ValueError, ReplayError):  # an unknown id: nothing of it is read
        path = None
    return found + ([path] if path is not None else [])


def run_inputs(run_dir, data_dir=None) -> list[Path]:
    """What exporting ``run_dir`` reads: the run directory, its dataset and mapping (from the manifest;
    for a campaign's directory, those of every stored configuration)."""
    run_dir = Path(run_dir)
    path = run_dir / "manifest.json"
    if (run_dir / "units").is_dir() and not path.exists():  # a campaign: every configuration's dataset
        from replay.campaign.store import Store

        found, store = [run_dir], Store(run_dir)
        dirs = store.data_dirs()
        for _, cfg in store.configs():
            params = cfg.get("dataset_params")
            found += dataset_inputs(
                cfg.get("dataset"),
                params.get("mapping") if isinstance(params, dict) else None,
                data_dir or dirs.get(cfg.get("dataset")),
            )  # the campaign's
        return list(dict.fromkeys(found))
    try:
        man = json.loads(path.read_text())
        cfg = man["config"]
        dataset, params = cfg["dataset"], cfg.get("dataset_params") or {}
    except FileNotFoundError:
        raise DataError(path, "no such file: not a `replay eval` output directory") from None
    except (OSError, ValueError, KeyError, TypeError) as e:
        raise DataError(path, f"not a replay manifest ({e})") from None
    found = [run_dir] + dataset_inputs(dataset, params.get("mapping") if isinstance(params, dict) else None, data_dir)
    recorded = man.get("dataset", {}).get("path") if isinstance(man.get("dataset"), dict) else None
    if isinstance(recorded, str) and recorded:
        found.append(Path(recorded))
    return found


# ---------------------------------------------------------------- ownership


def mcap_library(path) -> str | None:
    """The library string of an MCAP file's Header record, or None if it is not an MCAP file."""
    try:
        with open(path, "rb") as fh:
            head = fh.read(8 + 9 + 4 + 1024)
    except OSError:
        return None
    if len(head) < 21 or head[:8] != b"\x89MCAP0\r\n" or head[8] != 0x01:
        return None
    k = struct.unpack_from("<I", head, 17)[0]
    at = 21 + k
    if at + 4 > len(head):
        return None
    n = struct.unpack_from("<I", head, at)[0]
    lib = head[at + 4 : at + 4 + n]
    return lib.decode("utf-8", "replace") if len(lib) == n else None


def bag_marker(path) -> str | None:
    """The :data:`MARK_KEY` value in a ROS 2 bag directory's metadata.yaml custom_data, or None."""
    from ruamel.yaml import YAML

    try:
        doc = YAML(typ="safe").load((Path(path) / "metadata.yaml").read_text())
        custom = doc["rosbag2_bagfile_information"].get("custom_data") or {}
        value = custom.get(MARK_KEY)
    except Exception:  # unreadable, not YAML, not a bag: not ours
        return None
    return value if isinstance(value, str) else None


def _is_ours(target: Path, kind: str) -> bool:
    if kind == "mcap":
        return mcap_library(target) == MCAP_LIBRARY
    return not any(target.iterdir()) or bag_marker(target) is not None


def check_target(out, inputs, kind: str, others=()) -> Path:
    """Refuse an export target before anything is computed; ``kind`` "mcap" or "ros2".

    Refused: overlap with ``inputs`` or with the other targets ``others``; an unwritable
    location; something at ``out`` that this tool did not write (or of the wrong kind).
    """
    what = "--mcap" if kind == "mcap" else "--ros2-bag"
    refuse_overlap(out, [p for p in inputs if p is not None], what)
    for other in others:
        if other is not None:
            a, b = Path(out).resolve(), Path(other).resolve()
            if a == b or a.is_relative_to(b) or b.is_relative_to(a):
                raise ReplayError(f"{what} {out}: overlaps the other export target {other}; give separate paths")
    p = Path(out)
    check_writable(p, what)
    if p.is_symlink():
        raise ReplayError(f"{what} {out}: is a symbolic link; give the real path")
    if not p.exists():
        return p
    if kind == "mcap":
        if p.is_dir():
            raise ReplayError(f"{what} {out}: is a directory; give a file name")
        if not _is_ours(p, kind):
            raise ReplayError(f"{what} {out}: exists and is not an MCAP written by replay; refusing to replace it")
    else:
        if not p.is_dir():
            raise ReplayError(f"{what} {out}: exists and is not a directory")
        if not _is_ours(p, kind):
            raise ReplayError(
                f"{what} {out}: exists and is not a ROS 2 bag written by replay "
                f"(no {MARK_KEY} in its metadata.yaml); refusing to replace it"
            )
    return p


# ---------------------------------------------------------------- staging


def temp_beside(target) -> Path:
    """The hidden temporary name of this process for ``target``."""
    target = Path(target)
    return target.with_name(f".{target.name}{_TMP}{os.getpid()}")


def _remove(path: Path) -> None:
    if path.is_symlink() or not path.is_dir():
        path.unlink(missing_ok=True)
    else:
        shutil.rmtree(path, ignore_errors=True)


def clean_stale(target) -> list[Path]:
    """Remove the hidden temporaries left beside ``target`` by exports that were killed; returns them."""
    target = Path(target)
    gone = []
    for p in target.parent.glob(glob.escape(f".{target.name}{_TMP}") + "*"):
        pid = p.name[len(target.name) + 1 + len(_TMP) :]
        if pid.isdigit() and (int(pid) == os.getpid() or not alive(int(pid))):
            _remove(p)
            gone.append(p)
    return gone


def _fsync(path: Path) -> None:
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def _oserror(what: str, target, e: OSError) -> ReplayError:
    return ReplayError(f"{what} {target}: cannot write: {e.strerror or e}")


@contextmanager
def staged_file(target, what: str = "output", kind: str = "mcap"):
    """Yield a temporary path beside ``target``; on success rename it over ``target`` (one step).

    An existing ``target`` is replaced only if it is ours (``kind``, see :func:`check_target`).
    """
    target = Path(target)
    tmp = temp_beside(target)
    try:
        target.parent.mkdir(parents=True, exist_ok=True)
        clean_stale(target)
    except OSError as e:
        raise _oserror(what, target, e) from None
    try:
        yield tmp
        _fsync(tmp)
        if target.exists() and (target.is_dir() or not _is_ours(target, kind)):
            raise ReplayError(f"{what} {target}: exists and was not written by replay; left as it is")
        os.replace(tmp, target)
        _fsync(target.parent)
    except OSError as e:
        _remove(tmp)
        raise _oserror(what, target, e) from None
    except BaseException:
        _remove(tmp)
        raise


def publish_dir(staged: Path, target: Path) -> None:
    """Put the directory ``staged`` at ``target``, replacing an old one as one step where possible."""
    if not target.exists() and not target.is_symlink():
        os.rename(staged, target)
    elif not exchange(staged, target):
        old = staged.with_name(staged.name + ".old")
        os.rename(target, old)  # a kill here leaves no target and the old one in the hidden directory
        os.rename(staged, target)


@contextmanager
def staged_dir(target, what: str = "output"):
    """Yield a path for a new directory named like ``target`` inside a hidden temporary
    directory beside it; on success swap it in for ``target`` and remove the old one."""
    target = Path(target)
    tmp = temp_beside(target)
    try:
        target.parent.mkdir(parents=True, exist_ok=True)
        clean_stale(target)
        tmp.mkdir()
    except OSError as e:
        raise _oserror(what, target, e) from None
    try:
        staged = tmp / target.name
        yield staged
        for f in staged.rglob("*"):
            if f.is_file():
                _fsync(f)
        if target.is_symlink() or (target.exists() and (not target.is_dir() or not _is_ours(target, "ros2"))):
            raise ReplayError(f"{what} {target}: exists and is not a ROS 2 bag written by replay; left as it is")
        publish_dir(staged, target)
        _fsync(target.parent)
    except OSError as e:
        raise _oserror(what, target, e) from None
    finally:
        _remove(tmp)
