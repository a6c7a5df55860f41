"""Adapters: read a recording into a :class:`replay.frame.Frame`.

Each adapter is a function ``load(path, **options) -> Frame``. It validates the
input, raises :class:`replay.util.errors.DataError` with one clear line on bad input,
and records in ``frame.report`` every sample or channel it dropped, flagged,
masked or repaired. ``ADAPTERS`` maps the adapter names used in dataset
manifests (``datasets/*.toml``) to ``"module:function"``.
"""

from replay.util.lookup import resolve

ADAPTERS = {
    "bohai-csv": "replay.adapters.bohai:load",
    "lake": "replay.adapters.lake:load",
    "bags": "replay.adapters.bags:load",
}


def get_adapter(name: str):
    """The loader function registered under ``name``."""
    return resolve(ADAPTERS, name, "adapter")
