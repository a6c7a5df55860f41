"""Checking a campaign file's values, each error ``file:line: key: message`` (:class:`Where`)."""

from __future__ import annotations

import os
import re
from pathlib import Path

from replay.util.errors import ReplayError, listed

MAX_NAME_BYTES = 240  # the name makes the directory runs/campaign-<name> (file names: 255 bytes)


class Where:
    """Finds the line of a key in the campaign text for error messages."""

    def __init__(self, path: Path, text: str):
        self.path, self.lines = path, text.splitlines()

    def line(self, key: str, value=None) -> int:
        pats = []
        if value is not None and isinstance(value, str):
            pats.append(re.compile(re.escape(f'"{value}"') + "|" + re.escape(f"'{value}'")))
        pats.append(re.compile(r"(^|[\s{,\[.])" + re.escape(str(key)) + r"\s*[=\]]"))
        for pat in pats:
            for i, text in enumerate(self.lines, 1):
                if pat.search(text.split("#", 1)[0]):
                    return i
        return 1

    def error(self, key: str, what: str, value=None) -> ReplayError:
        return ReplayError(f"{self.path}:{self.line(key, value)}: {listed([str(key)])}: {what}")


def check_name(where, name: str) -> None:
    """A campaign name must be a plain name: it becomes the directory ``runs/campaign-<name>``,
    and a separator, ``..`` or an absolute path would place the output elsewhere."""
    seps = {"/", "\\", os.sep} | ({os.altsep} if os.altsep else set())
    bad = (
        "it is empty"
        if not name.strip()
        else "it is an absolute path"
        if os.path.isabs(name)
        else "it contains a path separator"
        if any(c in name for c in seps)
        else "it is . or .."
        if name in (".", "..")
        else "it contains a control character"
        if any(ord(c) < 32 or ord(c) == 127 for c in name)
        else f"it is {len(name.encode())} bytes long, at most {MAX_NAME_BYTES}"
        if len(name.encode()) > MAX_NAME_BYTES
        else None
    )
    if bad:
        shown = name if len(name) <= 60 else name[:40] + "..."
        raise where.error(
            "name",
            f"{shown!r} is not a plain name ({bad}; the output would not be "
            f"runs/campaign-<name>): use letters, digits, '-', '_' or '.'",
            name,
        )


def check_params(where, owner: str, declarations, params: dict) -> None:
    """Each parameter against its declaration: an unknown name, a wrong type or a value out of
    bounds -> ``file:line: key: message``."""
    known = {p.name: p for p in declarations}
    for key, value in params.items():
        if key not in known:
            raise where.error(key, f"{owner} has no parameter {key!r} (known: {', '.join(known) or 'none'})")
        try:
            known[key].check(value, owner)
        except ReplayError as e:
            raise where.error(key, str(e), value) from None
