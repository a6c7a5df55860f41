"""Progress of a campaign: :class:`replay.util.progress.Progress` labelled ``campaign``, units weighted
by their expected cost."""

from __future__ import annotations

from replay.util.progress import Progress as _Progress


class Progress(_Progress):
    def __init__(self, total: int, quiet: bool = False, stream=None, every: float = 10.0, total_weight=None):
        super().__init__(total, quiet, stream, every, label="campaign", unit="unit", total_weight=total_weight)
