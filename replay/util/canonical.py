"""A configuration's canonical JSON (:func:`plain`: numpy values, tuples and paths made plain) and its
hash (:func:`config_hash`), the one name of a configuration in leaderboards, campaigns and manifests.
Light on purpose (json, hashlib, numpy): ``replay score`` names its rows without loading the filters."""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import numpy as np


def config_hash(config: dict) -> str:
    """The hash of a configuration's canonical JSON (16 hex digits); the one name of a configuration."""
    text = json.dumps(plain(config), sort_keys=True, default=str)
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def plain(obj):
    """``obj`` with numpy values, tuples and paths made JSON-plain (lists, floats, ints, strings)."""
    if isinstance(obj, dict):
        return {str(k): plain(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [plain(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, (np.floating, np.integer, np.bool_)):
        return obj.item()
    if isinstance(obj, Path):
        return str(obj)
    return obj
