"""The training and test parts of ``replay tune`` read once before any trial: their size and their overlap.

Overlap is decided on content, not on names. Each part is the data it reads (a recording's
SHA-256, the frame's ``meta["sha256"]`` the data layer computes: the same file by another
path, a byte-identical copy or a registered id and its file are one recording; a simulator
with its master seed) and the time span, in the recording's own time, of the samples its views
(window, segment) keep. A training and a test part overlap iff they read the same data and
their spans intersect (closed intervals): ``segment`` ``0:0.6`` and ``0.6:1`` of one file do not
(the first ends at its last sample before 0.6·D, the second starts at its first sample from
0.6·D), a window and a segment are compared in seconds. ``rate`` and ``first`` are left out of
the span (a resampled grid point takes samples within the cut only; ``first`` only shortens
it), so a span is never narrower than the data a part reads.

Each part must hold at least :data:`MIN_SAMPLES` samples after its views and ``first``
(simulators: run 0's frame): fewer cannot rank one set of parameters above another.
"""

from __future__ import annotations

from dataclasses import dataclass

from replay.util.errors import ReplayError
from replay.util.params import Param
from replay.data import views
from replay.run.pipeline import load_frame

MIN_SAMPLES = Param(
    "min_samples",
    int,
    10,
    "the fewest samples each training and test part of replay tune must hold (after its views and --first)",
    low=2,
)


@dataclass(frozen=True)
class Part:
    """What one part reads: ``data`` (``("sha256", hex)`` or ``("sim", id, seed)``), its span in seconds
    of the recording's own time (``lo``..``hi``, closed) and its samples ``n``."""

    data: tuple
    lo: float
    hi: float
    n: int

    def meets(self, other: "Part") -> bool:
        return self.data == other.data and max(self.lo, other.lo) <= min(self.hi, other.hi)

    def data_text(self) -> str:
        return f"sha256 {self.data[1][:16]}" if self.data[0] == "sha256" else " ".join(map(str, self.data[1:]))


def read(dataset: str, params: dict, *, seed: int, first, data_dir, ref, where: str) -> Part:
    """The :class:`Part` of ``dataset`` under ``params`` (canonical, views included); ``where``
    names the option that made it in the one-line refusals (a view that keeps too little)."""
    chosen, own = views.split(params)
    cfg = {"dataset": ref.id, "dataset_params": own, "first": None, "seed": seed, "adapter": None}
    base = load_frame(cfg, 0, data_dir, ds=ref.entry)  # the whole recording (cached per file)
    try:
        used = views.apply(base, chosen, dataset).head(first)
        cut = views.apply(base, {k: v for k, v in chosen.items() if k != "rate"}, dataset)
    except ReplayError as err:
        text = str(err)
        raise ReplayError(f"{where}: {text[len(dataset) + 2 :] if text.startswith(dataset + ': ') else text}") from None
    if len(used.t) < MIN_SAMPLES.default:
        raise ReplayError(
            f"{where}: it holds {len(used.t)} sample{'s' * (len(used.t) != 1)}; a part to tune or test on "
            f"needs at least {MIN_SAMPLES.default} ({MIN_SAMPLES.name})"
        )
    offset = float((cut.meta.get("view") or {}).get("offset_s", 0.0))
    if ref.is_sim:
        data = ("sim", ref.id, seed)
    else:
        sha = base.meta.get("sha256")
        data = ("sha256", sha) if sha else ("path", str(base.meta.get("path") or ref.id))
    return Part(data, float(cut.t[0]) + offset, float(cut.t[-1]) + offset, len(used.t))


def overlap(train: list, test: list) -> str | None:
    """What the training and test parts share ([(description, Part)] each), or None."""
    found = []
    for a, p in train:
        for b, q in test:
            if p.meets(q):
                span = f"{max(p.lo, q.lo):g}..{min(p.hi, q.hi):g} s"
                same = f"{a} in both" if a == b else f"{a} and {b} are the same data ({p.data_text()})"
                found.append(f"{same}, both reading {span}")
    return "; ".join(found) or None
