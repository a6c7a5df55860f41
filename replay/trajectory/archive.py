"""The results archive of ``replay score --save-results DIR`` (evo's ``--save_results``, rpg's cached
results), read back by ``replay res`` without the inputs.

``DIR`` holds one set, written into a staging directory beside it and moved into place in one step
(:class:`replay.util.output_set.OutputSet`: a crash leaves the previous archive or the new one; an existing
``DIR`` is replaced only when it is an archive of ours):

* ``results.json`` — ``format``, ``version``, the replay version, the reference (source, name, poses,
  first and last stamp), the settings (those of :meth:`replay.trajectory.score_options.ScoreOptions.settings`) and their
  ``config_hash``; per estimate: ``name``, ``source``, ``trial_of``/``trial`` (``--trials``), ``matched``,
  the alignment ``transform`` (``R`` 3x3, ``t``, ``scale``: x -> scale R x + t), the statistics of every
  APE/RPE relation and, with ``--lengths``, per length; ``leaderboard``: the rows ``-o`` writes; ``files``:
  the SHA-256 of every other file; ``results_sha256``: the SHA-256 of ``results.json`` itself (its canonical
  JSON without that key, :mod:`replay.util.sealed`), so the statistics are covered too. Floats are written
  in full (JSON's shortest round-trip text; ``NaN`` for a missing number).

:func:`load` verifies all of it before anything is used, and refuses in one line naming the file: a
``results.json`` whose content differs from its own SHA-256 (an edited statistic), a ``files`` list that
is empty or lacks ``ape.parquet`` or ``leaderboard.csv`` (every archive has both), a listed file that is
missing or whose SHA-256 differs; then every APE/RPE statistic is recomputed from the errors kept in
``ape.parquet``/``rpe.parquet`` and must agree (relative 1e-9), so an edit whose checksums were
recomputed is refused too (the per-length statistics and the leaderboard rows are covered by the
checksums only). Archives of version 1 (before the seal) are refused with the command that recreates them: their
statistics were never covered by a checksum, so nothing they print could be verified.
* ``ape.parquet`` — per matched pose: ``estimate``, ``t`` (reference stamp), ``t_estimate``, one column per
  relation, ``err_x, err_y, err_z`` (aligned estimate minus reference) and ``ref_x, ref_y, ref_z``;
* ``rpe.parquet`` — per pair (when the RPE was computed): ``estimate``, ``t_i``, ``t_j``, the relations,
  ``err_x..z``, ``i``, ``j`` (the pair's rows among the estimate's rows of ``ape.parquet``);
* ``lengths.parquet`` — per sub-trajectory (``--lengths``): ``estimate``, ``length``, ``length_m``, ``i``,
  ``j``, ``t_i``, ``t_j`` and the six relative errors;
* ``leaderboard.csv`` — the same rows as ``-o``, every digit.
"""

from __future__ import annotations

import hashlib
import json
import math
from pathlib import Path

import numpy as np

from replay.util.canonical import config_hash, plain
from replay.trajectory.lengths import ERRORS as LENGTH_ERRORS
from replay.util import sealed
from replay.util.errors import ReplayError
from replay.trajectory.lengths import statistics as length_stats
from replay.trajectory.pose_error import statistics
from replay.util.version import __version__
from replay.scoring.summary import columns
from replay.util.files import write_csv
from replay.util.output_set import OutputSet

# pandas (1.5 s to import, measured with `python -X importtime` on the 2-core machine under load) and
# matplotlib (1.3 s) are imported inside the functions that need them: `replay score` without tables,
# archives or plots, and every other command, load neither.

KIND = "replay score results"
FORMAT = "replay-score-results"
VERSION = 2  # 2: results.json sealed (results_sha256); 1 is refused (load)
META = "results.json"
SEAL = "results_sha256"
REQUIRED = ("ape.parquet", "leaderboard.csv")
WHAT = "--save-results"


def check(out, inputs) -> None:
    """Every check of ``DIR`` that can be made before scoring (one line naming it)."""
    OutputSet(out, KIND, what=WHAT, inputs=inputs).check()


def _trial_of(row: dict):
    return (row["filter"][len("recorded:") :], int(row["trial"])) if row.get("trial", "") != "" else (None, None)


def frames(result) -> dict:
    """The per-pose, per-pair and per-sub-trajectory tables of a :class:`ScoreResult` (module docstring)."""
    # lazy: start-up, pandas measured ~740 ms: `replay score` imports this module, pandas only for tables
    import pandas as pd  # noqa: PLC0415

    ape = result.errors("ape")
    ref = np.concatenate([s.reference.p for s in result.scores.values()])
    ape = ape.assign(ref_x=ref[:, 0], ref_y=ref[:, 1], ref_z=ref[:, 2])
    out = {"ape": ape}
    if any(s.rpe_pairs is not None for s in result.scores.values()):
        pairs = [s.rpe_pairs for s in result.scores.values() if s.rpe_pairs is not None]
        out["rpe"] = result.errors("rpe").assign(
            i=np.concatenate([i for i, _ in pairs]), j=np.concatenate([j for _, j in pairs])
        )
    parts = []
    for name, s in result.scores.items():
        for label, entry in s.lengths.items():
            i, j = entry["pairs"]
            cols = {
                "estimate": name,
                "length": label,
                "length_m": entry["length"],
                "i": i,
                "j": j,
                "t_i": s.reference.t[i],
                "t_j": s.reference.t[j],
            }
            cols.update({e: entry[e] for e in LENGTH_ERRORS})
            parts.append(pd.DataFrame(cols))
    if parts:
        out["lengths"] = pd.concat(parts, ignore_index=True)
    return out


def meta(result, reference: str | None = None) -> dict:
    """The content of ``results.json`` but ``files`` (module docstring)."""

    ref = result.reference
    settings = plain(result.settings)
    estimates = []
    for (name, s), row in zip(result.scores.items(), result.rows):
        R, t, c = s.transform
        trial_of, trial = _trial_of(row)
        estimates.append(
            {
                "name": name,
                "source": json.loads(row["params"]).get("source", ""),
                "trial_of": trial_of,
                "trial": trial,
                "matched": len(s.reference),
                "unmatched": s.unmatched,
                "transform": {
                    "R": np.asarray(R, float).tolist(),
                    "t": np.asarray(t, float).tolist(),
                    "scale": float(c),
                },
                "stats": {
                    kind: {rel: statistics(e) | {"n": len(e)} for rel, e in errs.items()}
                    for kind, errs in (("ape", s.ape), ("rpe", s.rpe))
                    if errs
                },
                "lengths": {
                    label: {
                        "length_m": entry["length"],
                        "gaps": entry["gaps"],
                        **{e: length_stats(entry[e]) for e in LENGTH_ERRORS},
                    }
                    for label, entry in s.lengths.items()
                },
            }
        )
    ref_source = reference or ref.source or ref.name
    return {
        "format": FORMAT,
        "version": VERSION,
        "replay_version": __version__,
        "reference": {
            "source": str(ref_source),
            "name": ref.name,
            "poses": len(ref),
            "t_first": float(ref.t[0]),
            "t_last": float(ref.t[-1]),
        },
        "settings": settings,
        "config_hash": config_hash({"reference": str(ref_source), **settings}),
        "estimates": estimates,
        "leaderboard": plain(result.output_rows()),
    }


def _sha256(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def save(result, out, *, reference: str | None = None) -> Path:
    """Write the archive of ``result`` into the directory ``out`` as one set (module docstring)."""

    content = meta(result, reference)
    tables = frames(result)
    with OutputSet(out, KIND, what=WHAT).staged() as d:
        for name, df in tables.items():
            df.to_parquet(d / f"{name}.parquet", index=False)
        rows = result.output_rows()
        write_csv(rows, d / "leaderboard.csv", columns(rows))
        content["files"] = {f.name: _sha256(f) for f in sorted(d.iterdir()) if f.is_file()}
        content = json.loads(json.dumps(content))  # what a reader parses: the seal is of that
        content[SEAL] = sealed.digest(content, SEAL)
        (d / META).write_text(json.dumps(content, indent=1) + "\n")
    return Path(out)


class Archive:
    """One archive read back (:func:`load`): ``path``, ``meta`` (results.json), :meth:`table` (a Parquet file)."""

    def __init__(self, path: Path, meta: dict, shown: str):
        self.path, self.meta, self.shown = path, meta, shown

    def table(self, name: str):
        # lazy: start-up, pandas measured ~740 ms: `replay score` imports this module, pandas only for tables
        import pandas as pd  # noqa: PLC0415

        f = self.path / f"{name}.parquet"
        return pd.read_parquet(f) if name + ".parquet" in self.meta["files"] else None


def load(path) -> Archive:
    """The archive in ``path``, checked (format, version, every file's SHA-256); one line otherwise."""
    shown, p = str(path), Path(path)
    if not p.is_dir():
        raise ReplayError(
            f"{shown}: {'no such directory' if not p.exists() else 'not a directory'} (replay res "
            "reads the directories replay score --save-results writes)"
        )
    f = p / META
    if not f.is_file():
        raise ReplayError(f"{shown}: not a results archive (no {META}; written by replay score --save-results DIR)")
    try:
        m = json.loads(f.read_text())
    except (OSError, UnicodeDecodeError, ValueError) as e:
        raise ReplayError(f"{shown}/{META}: unreadable ({str(e)[:80]})") from None
    if not isinstance(m, dict) or m.get("format") != FORMAT:
        raise ReplayError(
            f"{shown}/{META}: not a replay score results file (format {str(m.get('format'))[:40]!r})"
            if isinstance(m, dict)
            else f"{shown}/{META}: not a replay score results file"
        )
    _verify(p, shown, m)
    if not m.get("estimates"):
        raise ReplayError(f"{shown}: an empty results archive (no estimate)")
    _agree(p, shown, m)
    return Archive(p, m, shown)


def _agree(p: Path, shown: str, m: dict) -> None:
    """Every APE/RPE statistic of ``results.json`` recomputed from ``ape.parquet``/``rpe.parquet``
    (relative 1e-9): the numbers printed are those of the errors kept, whatever the checksums say."""
    # lazy: start-up, pandas measured ~740 ms: `replay score` imports this module, pandas only for tables
    import pandas as pd  # noqa: PLC0415

    tables = {}
    for e in m["estimates"]:
        for kind, by_rel in (e.get("stats") or {}).items():
            if kind not in tables:
                f = p / f"{kind}.parquet"
                tables[kind] = pd.read_parquet(f) if f"{kind}.parquet" in m["files"] else None
            t = tables[kind]
            rows = t[t["estimate"] == e["name"]] if t is not None and "estimate" in t else None
            for rel, st in by_rel.items():
                if rows is None or rel not in rows:
                    raise ReplayError(f"{shown}/{META}: {e['name']} {kind} {rel}: no such errors in {kind}.parquet")
                v = rows[rel].to_numpy(float)
                v = v if len(v) == st.get("n") else v[~np.isnan(v)]
                found = statistics(v) | {"n": len(v)}
                for k, want in st.items():
                    got = found.get(k)
                    same = (
                        got is not None
                        and want is not None
                        and ((math.isnan(got) and math.isnan(want)) or math.isclose(got, want, rel_tol=1e-9, abs_tol=0))
                    )
                    if not same:
                        raise ReplayError(
                            f"{shown}/{META}: {e['name']} {kind} {rel} {k} {want!r} disagrees with its errors in "
                            f"{kind}.parquet ({got!r}): edited or damaged"
                        )


def _verify(p: Path, shown: str, m: dict) -> None:
    """The version, the seal of ``results.json`` and every listed file's SHA-256 (module docstring)."""
    again = f"recreate it with replay score REF EST... --save-results {shown}"
    if m.get("version") == 1:
        raise ReplayError(
            f"{shown}/{META}: archive version 1, written before results.json carried its own SHA-256: its "
            f"statistics cannot be verified; {again}"
        )
    if m.get("version") != VERSION:
        raise ReplayError(f"{shown}/{META}: archive version {m.get('version')!r}, this replay reads {VERSION}")
    if m.get(SEAL) != sealed.digest(m, SEAL):
        raise ReplayError(f"{shown}/{META}: content differs from its SHA-256 ({SEAL}): edited or damaged; {again}")
    files = m.get("files")
    if not isinstance(files, dict) or not all(isinstance(v, str) for v in files.values()):
        raise ReplayError(f"{shown}/{META}: 'files' is not a table of file names and SHA-256s; {again}")
    lacking = [f for f in REQUIRED if f not in files]
    if lacking:
        listed = "lists no files" if not files else f"does not list {', '.join(lacking)}"
        raise ReplayError(f"{shown}/{META}: {listed} (every archive holds {', '.join(REQUIRED)}); {again}")
    for name, digest in files.items():
        q = p / name
        if "/" in name or name in (".", "..", META) or not q.is_file():
            raise ReplayError(f"{shown}: {name} is missing (listed in {META})")
        if _sha256(q) != digest:
            raise ReplayError(f"{shown}/{name}: damaged (its SHA-256 differs from the one in {META})")


def finite(v):
    """A JSON number read back: NaN stays NaN, None (a missing number) becomes NaN."""
    return math.nan if v is None else v
