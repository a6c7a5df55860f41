"""A frame as pandas DataFrames (``Frame.to_pandas``, ``replay.frame_table``).

Duck-typed on :class:`replay.frame.Frame` (``t``, ``channels``, ``reference``,
``epoch``, ``meta``, ``report``), so that this leaf module imports nothing of replay.

* Index: ``t``, seconds from the first sample (``time="utc"``: absolute UTC times,
  when the frame has an ``epoch``).
* One column per channel component: ``name`` for a one-component channel, else
  ``name.component`` (``name.0``, ``name.1``... when the components are not named).
* Validity: samples a channel marks not valid are NaN (``masks=False``, the default);
  with ``masks=True`` the values are kept as read and each channel adds a boolean
  column ``name.valid``.
* The reference (ground truth) is kept apart: ``reference=True`` gives the reference
  channels instead of the sensor channels.
* ``df.attrs``: ``units`` (column -> unit), ``frames`` (column -> frame),
  ``epoch``, ``crs``, ``origin`` and ``group`` ("channels" or "reference").
"""

from __future__ import annotations

import numpy as np

from replay.util.errors import ReplayError


def column_names(name: str, channel) -> list[str]:
    """The columns of one channel (module docstring)."""
    width = 1 if np.ndim(channel.values) == 1 else int(np.prod(np.shape(channel.values)[1:]))
    comps = tuple(channel.components or ())
    if width == 1:
        return [name]
    return [f"{name}.{c}" for c in comps] if len(comps) == width else [f"{name}.{i}" for i in range(width)]


def frame_table(frame, *, reference: bool = False, masks: bool = False, time: str = "relative"):
    """The frame's sensor channels (``reference=True``: its reference channels) as a DataFrame."""
    # lazy: start-up, pandas measured ~740 ms: replay.frame imports this module
    import pandas as pd  # noqa: PLC0415

    if time not in ("relative", "utc"):
        raise ReplayError(f"time must be 'relative' or 'utc' (got {time!r})")
    group = frame.reference if reference else frame.channels
    n = len(frame.t)
    data, units, frames = {}, {}, {}
    for name, ch in group.items():
        values = np.asarray(ch.values, float).reshape(n, -1)
        valid = np.asarray(ch.valid, bool)
        for i, col in enumerate(column_names(name, ch)):
            data[col] = values[:, i].copy() if masks else np.where(valid, values[:, i], np.nan)
            units[col], frames[col] = ch.unit, ch.frame
        if masks:
            data[f"{name}.valid"] = valid.copy()
    index = pd.Index(np.asarray(frame.t, float), name="t")
    if time == "utc":
        if frame.epoch is None:
            raise ReplayError("time='utc': this frame has no epoch (its source records no absolute time)")
        index = pd.DatetimeIndex(pd.to_datetime(frame.epoch + index.to_numpy(), unit="s", utc=True), name="utc")
    df = pd.DataFrame(data, index=index)
    meta = getattr(frame, "meta", {}) or {}
    df.attrs.update(
        units=units,
        frames=frames,
        epoch=frame.epoch,
        crs=meta.get("crs"),
        origin=meta.get("origin"),
        group="reference" if reference else "channels",
    )
    return df


def report_table(frame):
    """The adapter's report (everything dropped, flagged, masked or repaired) as a DataFrame."""
    # lazy: start-up, pandas measured ~740 ms: replay.frame imports this module
    import pandas as pd  # noqa: PLC0415

    return pd.DataFrame(frame.report.to_list(), columns=["action", "what", "count", "reason"])
