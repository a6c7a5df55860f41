"""One colour per filter, the same in every figure: a fixed palette keyed by filter name.

Every filter of the registry has its own colour (:data:`FIXED`); another name gets one
from :data:`SPARE` by a stable hash of the name, so ``ekf`` is the same blue in every
plot, every report and every reproduction. Black and grey are kept for the reference,
the chi-square bands and context lines.

A label with parameters (``ukf(alpha=0.5)``: a campaign's grid) keeps the hue of its
filter: :class:`Palette`, built from all labels of a page, gives the variants of one filter
distinct shades (darker to lighter) and line styles, and resolves two unknown names that
hash to the same spare colour, so that two labels of a page never share a colour.

This module imports nothing of replay nor matplotlib (the report, the Python API's plots
and the reproductions can all use it)::

    from replay.outputs.palette import Palette, colour
    pal = Palette(["ekf", "ukf(alpha=0.5)", "ukf(alpha=1.0)", "pf"])
    ax.plot(t, y, **pal.style("ukf(alpha=0.5)"), label="ukf(alpha=0.5)")
"""

from __future__ import annotations

import colorsys
import zlib

REFERENCE = "#000000"  # the reference trajectory
BAND = "#7f7f7f"  # chi-square consistency bands
CONTEXT = "#b0b0b0"  # other filters drawn for context in a per-filter panel

FIXED = {
    "ekf": "#1f77b4",  # blue
    "ukf": "#ff7f0e",  # orange
    "ckf": "#2ca02c",  # green
    "pf": "#d62728",  # red
    "kf": "#9467bd",  # purple
    "aukf": "#8c564b",  # brown
    "gpf": "#e377c2",  # pink
    "mmpf": "#bcbd22",  # olive
    "stckf": "#17becf",  # cyan
    "stcpf": "#393b79",  # indigo
    "igwo-stcpf": "#a55194",  # plum
    "gwo-pf": "#637939",  # moss
    "igwo-pf": "#bd9e39",  # ochre
    "pso-pf": "#6b6ecf",  # periwinkle
    "pso-cpf": "#e7969c",  # salmon
    "wf-pf": "#843c39",  # maroon
}
SPARE = [
    "#3182bd",
    "#e6550d",
    "#31a354",
    "#756bb1",
    "#636363",
    "#fd8d3c",
    "#74c476",
    "#9e9ac8",
    "#d6616b",
    "#8ca252",
    "#ce6dbd",
    "#de9ed6",
    "#5254a3",
    "#b5cf6b",
    "#e7ba52",
    "#ad494a",
]
STYLES = ["-", "--", ":", "-."]


def filter_of(label: str) -> str:
    """The filter name of a label: ``ukf(alpha=0.5)`` -> ``ukf`` (lower case)."""
    return str(label).split("(", 1)[0].strip().lower()


def colour(name: str) -> str:
    """The fixed colour of a filter name (a label's filter), as ``#rrggbb``."""
    f = filter_of(name)
    return FIXED.get(f) or SPARE[zlib.crc32(f.encode()) % len(SPARE)]


def shade(hex_colour: str, i: int, n: int) -> str:
    """Variant ``i`` of ``n`` of a colour: the same hue, lightness from darker to lighter."""
    if n <= 1:
        return hex_colour
    r, g, b = (int(hex_colour[k : k + 2], 16) / 255 for k in (1, 3, 5))
    h, light, s = colorsys.rgb_to_hls(r, g, b)
    lo, hi = max(0.2, light - 0.16), min(0.72, light + 0.16)
    light = lo + (hi - lo) * i / (n - 1)
    r, g, b = colorsys.hls_to_rgb(h, light, s)
    return "#" + "".join(f"{round(v * 255):02x}" for v in (r, g, b))


class Palette:
    """The colours of one page: every label its own colour, the filter's hue for all its labels."""

    def __init__(self, labels):
        labels = list(dict.fromkeys(str(x) for x in labels))
        by_filter: dict[str, list[str]] = {}
        for lab in labels:
            by_filter.setdefault(filter_of(lab), []).append(lab)
        base, used = {}, set()
        for f in sorted(by_filter, key=lambda f: (f not in FIXED, f)):  # registry names first, then by name
            c = colour(f)
            if c in used:  # two unknown names on one hash: the next free spare, then any free colour
                k = SPARE.index(c)
                c = next((x for x in SPARE[k:] + SPARE[:k] + list(FIXED.values()) if x not in used), c)
            base[f] = c
            used.add(c)
        self._colour, self._ls = {}, {}
        for f, labs in by_filter.items():
            labs = sorted(labs)
            for i, lab in enumerate(labs):
                self._colour[lab] = shade(base[f], i, len(labs))
                self._ls[lab] = STYLES[i % len(STYLES)] if len(labs) > 1 else "-"
        self.labels = labels

    def colour(self, label) -> str:
        label = str(label)
        return self._colour[label] if label in self._colour else colour(label)

    def linestyle(self, label) -> str:
        return self._ls.get(str(label), "-")

    def style(self, label) -> dict:
        """``color`` and ``linestyle`` keywords for matplotlib's ``plot``."""
        return {"color": self.colour(label), "linestyle": self.linestyle(label)}

    def items(self):
        """(label, colour) in the page's order."""
        return [(lab, self.colour(lab)) for lab in self.labels]
