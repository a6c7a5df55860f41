"""The one TOML loader of the files a user names: mappings, campaign files (``--tuned`` too),
``--space`` and dataset manifests.

The text is read by :func:`replay.util.regular.read_text` (a regular file, size-capped); a
syntax error, and a nesting deeper than :data:`MAX_DEPTH` (a "nesting bomb" would end
``tomllib`` or any later walk of the document in a ``RecursionError``), is one line naming
the file.
"""

from __future__ import annotations

import tomllib

from replay.util.errors import DataError
from replay.util.regular import read_text

MAX_DEPTH = 32  # tables and arrays inside one another; a replay file needs 4


def depth(doc) -> int:
    """How deeply tables and arrays nest in ``doc`` (a scalar: 0), without recursion."""
    deepest, todo = 0, [(doc, 1)]
    while todo:
        node, level = todo.pop()
        if isinstance(node, (dict, list)):
            deepest = max(deepest, level)
            todo.extend((x, level + 1) for x in (node.values() if isinstance(node, dict) else node))
    return deepest


def loads(text: str, source, what: str) -> dict:
    """The parsed TOML ``text`` of ``source``, or one line naming it."""
    try:
        doc = tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise DataError(source, f"not valid TOML: {str(e).splitlines()[0]}") from None
    except RecursionError:
        doc = None
    if doc is None or depth(doc) > MAX_DEPTH:
        raise DataError(source, f"tables or arrays nested more than {MAX_DEPTH} deep: not {what}")
    return doc


def load(path, what: str, source=None) -> tuple[dict, str]:
    """(document, text) of the TOML file ``path``; one line naming it (``source``, default the
    path) when it is not a small regular file of valid TOML."""
    text = read_text(path, what, source)
    return loads(text, path if source is None else source, what), text
