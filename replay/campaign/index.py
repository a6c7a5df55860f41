"""``OUT/configs.json``: the configurations a campaign directory holds, in one file.

``{"configs": {config_hash: configuration}, "data_dirs": {dataset id: directory}, "names": {dataset id:
id as written}}``,
written once per ``campaign run`` (atomically, one ``fsync``) before any unit is
computed, instead of one flushed ``units/<hash>/config.json`` per configuration up
front (25,000 configurations: 25,000 flushes before the first unit). Each
configuration's ``config.json`` is written with its first stored units.

The index is the store's list of configurations: a configuration it names whose
``units/<hash>`` directory is gone (or is a file) is an error naming it, never a
silently missing row. ``data_dirs``: the ``data_dir`` the campaign ran each file
dataset with (``--data-dir``, else ``[campaign] data_dir``), which ``replay export``
uses when it is given none. ``names``: a recording's id as its campaign file writes it (relative to
the file), which the tables show instead of the absolute path the configurations hold (what a unit
needs to be computed again). Stores written before the index have none: their
configurations are those of the ``units/`` directories.
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

NAME = "configs.json"


def _body(configs: dict, data_dirs: dict, names: dict | None) -> dict:
    return {"configs": configs, "data_dirs": data_dirs} | ({"names": names} if names else {})  # none: as before


def _checksum(configs: dict, data_dirs: dict, names: dict | None = None) -> str:
    text = json.dumps(_body(configs, data_dirs, names), sort_keys=True, separators=(",", ":"), default=str)
    return hashlib.sha256(text.encode()).hexdigest()


def read(out) -> tuple[dict, dict, str | None]:
    """(configs, data_dirs, problem): ``problem`` one line naming the file when it is damaged
    (then both dicts are empty); a missing index is ``({}, {}, None)``. The index holds the
    SHA-256 of its content (one hash, not one configuration hash per entry: 25,000 of those
    take seconds)."""
    configs, dirs, _, problem = _read(out)
    return configs, dirs, problem


def names(out) -> dict:
    """{dataset id: the id as its campaign file writes it} (empty for a damaged index or an older store)."""
    return _read(out)[2]


def _read(out) -> tuple[dict, dict, dict, str | None]:
    path = Path(out) / NAME
    try:
        raw = path.read_bytes()
    except FileNotFoundError:
        return {}, {}, {}, None
    except OSError as err:
        return {}, {}, {}, f"{path}: cannot read ({err.strerror})"
    try:
        doc = json.loads(raw)
    except (ValueError, UnicodeDecodeError):
        return {}, {}, {}, f"{path}: {'zero-length' if not raw.strip() else 'not valid JSON'}"
    configs = doc.get("configs") if isinstance(doc, dict) else None
    dirs = doc.get("data_dirs", {}) if isinstance(doc, dict) else None
    shown = doc.get("names", {}) if isinstance(doc, dict) else None
    if (
        not isinstance(configs, dict)
        or not isinstance(dirs, dict)
        or not isinstance(shown, dict)
        or not all(isinstance(c, dict) for c in configs.values())
    ):
        return {}, {}, {}, f"{path}: not a campaign's configuration index"
    if doc.get("sha256") != _checksum(configs, dirs, shown):
        return {}, {}, {}, f"{path}: content differs from the checksum it holds (edited or damaged)"
    text = lambda d: {k: v for k, v in d.items() if isinstance(v, str)}  # noqa: E731
    return configs, text(dirs), text(shown), None


def document(configs: dict, data_dirs: dict, names: dict | None = None) -> dict:
    """What the index file holds (written by :func:`replay.util.files.write_json`)."""
    return _body(configs, data_dirs, names) | {"sha256": _checksum(configs, data_dirs, names)}


def describe(cfg: dict) -> str:
    """A configuration in a few words, for error lines."""
    return f"{cfg.get('dataset')} {cfg.get('task')} {cfg.get('filter')}"
