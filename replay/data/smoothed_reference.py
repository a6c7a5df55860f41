"""``reference = FILE`` (``replay eval --reference FILE``): a track written by ``replay export --tum``
(a smoothed row: :mod:`replay.outputs.export_reference`) as the frame's position reference.

A dataset parameter, like the views (:mod:`replay.data.views`), so it is part of the
configuration: its hash, the manifest (``dataset_params.reference``), ``replay rerun``. Applied
after the other views (window, segment, rate): the file's times are seconds from the recording's
first sample, the frame's time plus its view's offset. Each sample of the frame takes the file's pose
whose stamp is within :data:`MATCH_S` of its time (else it has no reference there: nothing is
interpolated); a file that matches no sample is refused. The reference's orientation channel
(``position_attitude``) is dropped: the file's heading is no roll-pitch-yaw reference.

Never silently: the file's provenance line (``reference: smoothed, gtsam-batch over odom +
gps``; a TUM file without replay's header is ``reference: FILE (TUM, no provenance recorded)``)
goes into ``meta["reference_provenance"]`` (the manifest's ``dataset`` section), the reference
channel's description and the frame's report; ``replay eval`` prints it above the table. A file
written from another dataset than this one is refused in one line.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import replace as changed
from pathlib import Path

import numpy as np

from replay.util.errors import DataError, ReplayError
from replay.frame import Channel, Report

MATCH_S = 1e-3  # a frame sample and a pose of the file are the same instant within this (s)


def read(path) -> tuple[dict, np.ndarray]:
    """(header ``{key: value}`` of the ``# key: value`` lines, (m, 8) rows ``t x y z qx qy qz qw``)."""
    path = Path(path)
    try:
        lines = path.read_text().splitlines()
    except FileNotFoundError:
        raise DataError(path, "no such reference file") from None
    except (OSError, UnicodeDecodeError) as e:
        raise DataError(path, f"cannot read the reference file ({e})") from None
    header, rows = {}, []
    for i, line in enumerate(lines, 1):
        s = line.strip()
        if s.startswith("#"):
            key, sep, value = s[1:].partition(":")
            if sep:
                header[key.strip()] = value.strip()
            continue
        if not s:
            continue
        try:
            row = [float(v) for v in s.split()]
        except ValueError:
            row = []
        if len(row) != 8 or not np.isfinite(row).all():
            raise DataError(path, f"line {i}: not a TUM pose 't x y z qx qy qz qw' of finite numbers")
        rows.append(row)
    data = np.array(rows, float).reshape(-1, 8)
    if not len(data) or np.any(np.diff(data[:, 0]) <= 0):
        raise DataError(path, "no pose, or stamps that do not increase" if len(data) else "no pose")
    return header, data


def _inputs(header: dict) -> dict:
    """{task input: frame channel} the smoothed track was computed from (the header's ``inputs``)."""
    try:
        found = json.loads(header.get("inputs") or "{}")
    except ValueError:
        return {}
    return {str(k): str(v) for k, v in found.items()} if isinstance(found, dict) else {}


def provenance_line(header: dict, path) -> str:
    return header.get("reference") or f"{Path(path).name} (TUM, no provenance recorded)"


def replace(frame, path, source: str = "dataset"):
    """``frame`` with its position reference taken from the file ``path`` (module docstring); a new
    frame: the input (perhaps cached) is not changed."""
    header, data = read(path)
    made_from, this = header.get("dataset"), frame.meta.get("dataset") or frame.meta.get("source")
    if made_from and this and Path(str(made_from)).name != Path(str(this)).name:
        raise ReplayError(f"{source}: reference {path} was made from {made_from}, not from this recording ({this})")
    t = np.asarray(frame.t, float) + float((frame.meta.get("view") or {}).get("offset_s") or 0.0)
    j = np.clip(np.searchsorted(data[:, 0], t), 1, len(data) - 1) if len(data) > 1 else np.zeros(len(t), int)
    j = np.where(np.abs(data[j - 1, 0] - t) <= np.abs(data[j, 0] - t), j - 1, j) if len(data) > 1 else j
    ok = np.abs(data[j, 0] - t) <= MATCH_S
    if not ok.any():
        raise ReplayError(
            f"{source}: reference {path}: none of its {len(data)} stamps is within {MATCH_S:g} s of a sample "
            f"(its times are seconds from the recording's first sample: {data[0, 0]:g} to {data[-1, 0]:g} s; "
            "the recording's samples: evaluate at the rate it was written at, e.g. --rate)"
        )
    dims = 2 if header.get("dims") == "2" else 3
    values = np.where(ok[:, None], data[j, 1 : 1 + dims], np.nan)
    line = provenance_line(header, path)
    old = frame.reference.get("position")
    ref = dict(frame.reference)
    ref.pop("position_attitude", None)
    ref["position"] = (
        changed(old, values=values, valid=ok, description=f"{line} ({Path(path).name})")
        if old is not None and old.width >= dims
        else _channel(values, ok, f"{line} ({Path(path).name})")
    )
    if old is not None and old.width > dims:
        ref["position"] = changed(ref["position"], components=tuple(old.components[:dims]))
    meta = dict(
        frame.meta,
        reference_provenance={  # the form replay.scoring.provenance reads: kind, source, built_from
            "kind": "smoothed track",
            "source": f"{line}; {Path(path).name}",
            "built_from": {
                ch: f"the smoothed track was computed from it ({header.get('filter', 'a smoother')})"
                for ch in sorted(set(_inputs(header).values()))
            },
            "reference": line,
            "file": Path(path).name,
            "sha256": hashlib.sha256(Path(path).read_bytes()).hexdigest(),  # rerun: the same file?
            "samples": int(ok.sum()),
            **header,
        },
    )
    out = changed(frame, channels=dict(frame.channels), reference=ref, meta=meta, report=_report(frame))
    out.report.add(
        "replaced",
        "reference position",
        int(ok.sum()),
        f"reference: {line}, from {Path(path).name} ({int(ok.sum())} of {len(t)} samples within "
        f"{MATCH_S:g} s of a pose)",
    )
    return out


def _channel(values, valid, description):
    axes = ("x", "y", "z")[: values.shape[1]]
    return Channel(values, "m", "enu", valid, axes, (), "", description)


def _report(frame):
    return Report(list(frame.report.entries))
