"""An adapter's options, declared once: :func:`declare` decorates ``load(path, **options)``.

Each option is a :class:`replay.util.params.Param` (type, default, bounds or choices,
unit, doc). The declarations drive ``replay list adapters``, the checking of a
dataset's options before any data is read (:func:`replay.data.registry.check_params`:
``replay eval --dataset-param``, the API, campaign files) and the call itself: the
decorated ``load`` refuses an unknown option or a value its declaration refuses
with one line (``adapter lake: max_gap must be a number > 0 (got 0)``) and passes
every option, defaults filled in, to the function (whose options have no defaults
of their own: they are written once, here).
"""

from __future__ import annotations

import functools

from replay.util.errors import ReplayError, shown
from replay.util.params import Param


def check(adapter: str, params: tuple[Param, ...], given: dict) -> dict:
    """The given options checked and normalised (only those given): an unknown name or a value
    its declaration refuses raises one line naming the adapter and the option."""
    known = {p.name: p for p in params}
    for name in given:
        if name not in known:
            raise ReplayError(f"adapter {adapter}: unknown option {shown(name)} (known: {', '.join(known) or 'none'})")
    return {name: known[name].check(value, f"adapter {adapter}") for name, value in given.items()}


def declare(adapter: str, *params: Param):
    """Decorate an adapter's ``load(path, *, option, ...)``: its options are ``params``.

    The decorated function carries them as ``PARAMS`` (and its name as ``ADAPTER``).
    """

    def wrap(load):
        @functools.wraps(load)
        def checked(path, **given):
            return load(path, **{**{p.name: p.default for p in params}, **check(adapter, params, given)})

        checked.PARAMS, checked.ADAPTER = params, adapter
        return checked

    return wrap
