"""Write a frame with depth, speed and pitch channels as a lake-trial log (the format: :mod:`replay.adapters.lake`)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from replay.adapters.lake_units import UNITS
from replay.frame import Frame


def write(frame: Frame, path, comments=(), pitch_unit: str = "deg") -> Path:
    """Write a frame with depth/speed/pitch channels (and reference) as a lake-trial log.

    Reference cells share the sensor row's time; invalid samples are empty cells.
    """
    path = Path(path)
    scale = {"depth": 1.0, "speed": 1.0, "pitch": 1.0 / UNITS["pitch"][pitch_unit]}
    suffix = {"depth": "m", "speed": "mps", "pitch": pitch_unit}
    data = {"time_s": frame.t}
    for prefix, group in (("", frame.channels), ("ref_", frame.reference)):
        for kind in ("depth", "speed", "pitch"):
            ch = group.get(kind)
            if ch is not None:
                data[f"{prefix}{kind}_{suffix[kind]}"] = np.where(ch.valid, ch.values * scale[kind], np.nan)
    lines = [f"# {c}" for c in ["replay lake-trial depth log (format: README.md, 'Lake-trial logs')", *comments]]
    table = pd.DataFrame(data)
    body = table.to_csv(index=False, float_format="%.10g", na_rep="", lineterminator="\n")
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text("\n".join(lines) + "\n" + body, encoding="utf-8")
    return path
