"""A built-in filter's quick case (its class's ``CASE``): where the test suite checks it.

Each built-in filter declares on its own class a registered simulator its model fits, the task,
the steps kept (``first``) and a few non-default parameters that keep a run small and exercise its
options. The suite derives its per-filter groups from these declarations (``tests/builtin_cases.py``:
``replay eval`` equals ``replay campaign run``, a rerun is exact, a changed number is refused), so a
new built-in filter is its file plus one line in ``FILTERS``; without a ``CASE`` of its own it is
checked on :data:`DEFAULT` (the sonar task of ``sim/auv-sonar``, 30 steps, its defaults).
"""

from __future__ import annotations

from dataclasses import dataclass, field


@dataclass(frozen=True)
class Case:
    dataset: str = "sim/auv-sonar"  # a registered simulator whose model the filter fits
    task: str = "sonar"
    params: dict = field(default_factory=dict)  # non-default parameters: small, and exercising options
    first: int | None = 30  # steps kept


DEFAULT = Case()


def case_of(cls) -> Case:
    """The case declared on ``cls`` itself (not inherited: a subclass is another filter), else :data:`DEFAULT`."""
    case = vars(cls).get("CASE", DEFAULT)
    if not isinstance(case, Case):
        raise TypeError(f"{cls.__module__}.{cls.__qualname__}.CASE: a replay.filters.case.Case, not {case!r}")
    return case
