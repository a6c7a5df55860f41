"""The corpus of malformed and hostile inputs (issue 12) holds at least 60 cases, each a one-line
refusal or a counted repair asserted in its own module (``tests/test_hostile_*.py``)."""
import importlib
from pathlib import Path

from hostile import CORPUS


def test_corpus_has_at_least_60_cases_across_input_kinds():
    here = Path(__file__).parent
    modules = sorted(p.stem for p in here.glob("test_hostile_*.py") if p.stem != "test_hostile_corpus")
    for name in modules:
        importlib.import_module(name)
    assert {"test_hostile_adapters", "test_hostile_http", "test_hostile_campaign", "test_hostile_outputs",
            "test_hostile_export"} <= set(modules)
    assert len(CORPUS) >= 60, sorted(CORPUS)
