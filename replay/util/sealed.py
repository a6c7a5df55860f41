"""The SHA-256 a JSON document holds of itself (unit records, results archives).

:func:`digest` hashes the document's canonical JSON: keys sorted, no spaces, ``NaN`` as JSON's
``NaN``, the document without its own checksum ``key``. A reader recomputes it on the parsed
document, so the text may be re-indented but no value may change. It detects damage and edits,
not a forger who recomputes it.
"""

from __future__ import annotations

import hashlib
import json


def canonical(doc: dict, key: str) -> bytes:
    """The bytes the checksum covers: ``doc`` without ``key``, keys sorted, compact."""
    body = {k: v for k, v in doc.items() if k != key}
    return json.dumps(body, sort_keys=True, separators=(",", ":"), allow_nan=True).encode()


def digest(doc: dict, key: str) -> str:
    """The SHA-256 (hex) of :func:`canonical`."""
    return hashlib.sha256(canonical(doc, key)).hexdigest()
