"""The built-in filters' test groups, derived from their declarations (``CASE`` on each filter's class,
:mod:`replay.filters.case`) instead of hand-kept tables: every built-in filter of ``FILTERS`` is in
exactly one group, the filters of one dataset, task and length together."""
from replay.filters import FILTERS
from replay.filters.case import case_of


def cases() -> dict:
    """{built-in filter name: its Case}."""
    return {name: case_of(FILTERS.load(name)) for name in FILTERS.builtin}


def groups() -> list[tuple]:
    """[(dataset, task, first, {filter: non-default params})], in the registry's order."""
    out: dict = {}
    for name, case in cases().items():
        out.setdefault((case.dataset, case.task, case.first), {})[name] = dict(case.params)
    return [(*key, filters) for key, filters in out.items()]


def group_id(group) -> str:
    """A group's test id: its task and its filters (``-k NAME`` selects a filter's group)."""
    return f"{group[1]}:{'+'.join(group[3])}"
