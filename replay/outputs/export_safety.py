"""Where exports (MCAP files, ROS 2 bag directories) may go, and how they replace an old one.

* **Never onto an input.** An export target may not equal, contain or lie inside what
  the export reads: the run directory, the dataset (CSV, MCAP, bag file or bag
  directory), the topic mapping (:func:`run_inputs`, :func:`dataset_inputs`), nor
  the other export target of the same command.
* **Only our own outputs are replaced.** An existing MCAP is replaced only when its
  Header record names ``replay`` as the writing library; an existing directory only
  when it is empty or a ROS 2 bag whose ``metadata.yaml`` carries :data:`MARK_KEY`
  in ``custom_data`` (written by :mod:`replay.outputs.export_ros2`). Anything else is refused in one
  line.
* **Old or new, never a mix.** Both are written through an :class:`OutputSet`
  (:func:`export_set`): a file to ``.<name>.staging-<pid>`` beside the target, fsynced
  and renamed over it; a bag directory made at such a hidden name and swapped in with
  one ``renameat2(RENAME_EXCHANGE)`` (or, where the kernel or file system lacks it, two
  renames: a kill between them leaves the old bag at ``.<name>.old-<pid>``, put back by
  the next export). A killed export leaves the old output (or none) and at most one
  hidden temporary, which the next export to the same target removes once its process
  is gone.
"""

from __future__ import annotations

import json
import struct
from pathlib import Path

from ruamel.yaml import YAML

from replay.campaign.store import Store
from replay.data import dataset_ref
from replay.util.errors import DataError, ReplayError
from replay.util.output_set import OutputSet

MARK_KEY = "replay.output"  # custom_data key of the ROS 2 bags written through staged_bag
MCAP_LIBRARY = "replay"  # the Header library string of the MCAP files replay writes


# ---------------------------------------------------------------- what an export reads


def dataset_inputs(dataset, mapping=None, data_dir=None) -> list[Path]:
    """The files a dataset id or path is read from (none for a simulator), and the mapping."""
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


def _owned(kind: str, what: str):
    """The ownership rule of an export target (:class:`OutputSet`'s ``rule``): absent, or ours."""

    def rule(p: Path, out) -> None:
        if p.is_symlink():
            raise ReplayError(f"{what} {out}: is a symbolic link; give the real path")
        if not p.exists():
            return
        if kind == "mcap":
            if p.is_dir():
                raise ReplayError(f"{what} {out}: is a directory; give a file name")
            if not _is_ours(p, kind):
                raise ReplayError(f"{what} {out}: exists and is not an MCAP written by replay; refusing to replace it")
        elif not p.is_dir():
            raise ReplayError(f"{what} {out}: exists and is not a directory")
        elif not _is_ours(p, kind):
            raise ReplayError(
                f"{what} {out}: exists and is not a ROS 2 bag written by replay "
                f"(no {MARK_KEY} in its metadata.yaml); refusing to replace it"
            )

    return rule


def export_set(out, kind: str, inputs=(), others=(), what: str | None = None) -> OutputSet:
    """The output set of an export to ``out`` (``kind`` "mcap": a file; "ros2": a bag directory,
    staged nested: the bag writer makes it and names its file after it). ``check()`` it before
    anything is computed; write it in ``with export_set(...).staged(nested=True) as tmp``."""
    what = what or ("--mcap" if kind == "mcap" else "--ros2-bag")
    return OutputSet(
        out,
        what=what,
        inputs=inputs,
        others=others,
        rule=_owned(kind, what),
        file=kind == "mcap",
        failed="cannot write: {why}",
    )


def check_target(out, inputs, kind: str, others=()) -> Path:
    """Refuse an export target before anything is computed (:meth:`OutputSet.check`); ``kind``
    "mcap" or "ros2". Refused: overlap with ``inputs`` or with the other targets ``others``; an
    unwritable or full location; something at ``out`` that this tool did not write (or of the
    wrong kind)."""
    export_set(out, kind, inputs, others).check()
    return Path(out)


def check_exports(mcap_out, ros2_out, inputs) -> None:
    """Refuse export targets before any work: onto or inside an input, onto each other,
    unwritable, or replacing something this tool did not write (one line each)."""
    if mcap_out:
        check_target(mcap_out, inputs, "mcap", others=[ros2_out])
    if ros2_out:
        check_target(ros2_out, inputs, "ros2", others=[mcap_out])


def check_eval_exports(out_dir, mcap_out, ros2_out, dataset, mapping=None, data_dir=None) -> None:
    """For ``replay eval --mcap/--ros2-bag``: the same refusals, before the evaluation runs (the
    inputs: the dataset's files, the mapping and the output directory ``out_dir``, which the
    targets may not lie in or around either: it is replaced as a whole)."""
    out = Path(out_dir).resolve()
    for opt, path in (("--mcap", mcap_out), ("--ros2-bag", ros2_out)):
        if path and (Path(path).resolve().is_relative_to(out) or out.is_relative_to(Path(path).resolve())):
            raise ReplayError(f"{opt} {path}: overlaps the output directory {out_dir}, which is replaced as a whole")
    if mcap_out or ros2_out:
        check_exports(mcap_out, ros2_out, [out_dir] + dataset_inputs(dataset, mapping, data_dir))
