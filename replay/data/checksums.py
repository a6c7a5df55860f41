"""Registered upstream checksums, and the checks of local copies of file datasets.

Also the content checks by adapter (:data:`CONTENT_CHECKS`) that a download without a
registered checksum must pass (``replay/data/fetch.py``).

``REGISTERED`` holds the SHA-256 and size (bytes) of every Bohai CSV that could be
obtained from the upstream repository (nature1949/AUV_navigation_dataset, branch
main): 10 of the 17 sequences, copied from the shared data's
``UPSTREAM_SHA256SUMS``. Four of them (20220625_0_1, 20220712_0_1, 20220719_6_1,
20230517_0_0) are not shipped with the shared data; their checksums let a
download be verified all the same. Constants only: nothing is read at run time.
The registry puts them on the manifest entries of the same id
(:func:`with_registered`); a download of one of these is verified by size and
checksum, the seven others are accepted only after a content check
(``replay/data/fetch.py``) and reported as "not registered upstream (content-checked)".

``checksums.json`` beside a downloaded file records what `fetch` saw of a file
without a registered checksum (its sha256, size, url, and that it passed the
content check), so that a later edit can be told ("changed"). It is never taken
for a registered checksum.
"""

from __future__ import annotations

import hashlib
import json
import logging
import os
import tempfile
from datetime import datetime, timezone
from dataclasses import dataclass, replace
from pathlib import Path

from replay.util.downloads import part_prefix
from replay.util.errors import ReplayError

CHECKSUMS_FILE = "checksums.json"
# checksum status of a file without a registered checksum that `fetch` content-checked
CONTENT_CHECKED = "not registered upstream (content-checked)"

# dataset id -> (upstream path, size in bytes, sha256)
REGISTERED: dict[str, tuple[str, int, str]] = {
    "bohai/20220625_0_0": (
        "20220625/0/20220625_0_0.csv",
        4093632,
        "7fd4ad89103e4e0a8fe4032f0c7e805be6d32db457fe2c64223034540132fce1",
    ),
    "bohai/20220625_0_1": (
        "20220625/0/20220625_0_1.csv",
        3161346,
        "c0d5440707b0ab6e53855407977dbe872f95d5b0922eb81b181edef84af6609f",
    ),
    "bohai/20220712_0_1": (
        "20220712_0_1.csv",
        353643,
        "3287424eafd36f5e3129ad9bd2c21c827fc9779338f4136e84b2a6ea6369973c",
    ),
    "bohai/20220719_6_1": (
        "20220719_6_1.csv",
        1557212,
        "4690ef43fafd4585b17a994f441babe049ad6db332f703381dd46bcf98ece24d",
    ),
    "bohai/20220822_0_0": (
        "20220822/0/20220822_0_0.csv",
        1071327,
        "db16c328bc2ffbc82d5053f1a93aee4630a4f6fa50aaaf2d83b7f2cbacc5b863",
    ),
    "bohai/20220822_0_3": (
        "20220822/0/20220822_0_3.csv",
        4146862,
        "5a188116182f20f4e9c0fde42d0ef360462ebc0e807a017010503da782872ea2",
    ),
    "bohai/20220822_0_4": (
        "20220822/0/20220822_0_4.csv",
        3711638,
        "13f6ab202bafb0e3ccb3ff1ad9ccde3cfe70f64b9dab86f7c4c3c2fd72e475ab",
    ),
    "bohai/20220822_0_5": (
        "20220822/0/20220822_0_5.csv",
        3462196,
        "6583147c352309ab3684537f3d98d20255cff38731fd2ad6b4cf861ee90673f7",
    ),
    "bohai/20220822_0_6": (
        "20220822/0/20220822_0_6.csv",
        3659129,
        "749001a1d5dbb4e110335528177d613702a91cce33cd9ebe7dfeae910faf12e8",
    ),
    "bohai/20230517_0_0": (
        "20230517_0_0.csv",
        1376002,
        "378ce66997c34fca339145a9504b0e0cf7818dfc59e25e081c28c43e6fc24d52",
    ),
}


def with_registered(ds, where: str):
    """``ds`` with its registered upstream path, size and checksum (``REGISTERED``);
    a manifest value that contradicts them is refused."""
    if ds.id not in REGISTERED:
        return ds
    upstream, size, sha = REGISTERED[ds.id]
    for name, want in (("upstream_path", upstream), ("size", size), ("sha256", sha)):
        if getattr(ds, name) not in (None, want):
            raise ReplayError(f"{where}: {name} {getattr(ds, name)} differs from the registered upstream {want}")
    return replace(ds, upstream_path=upstream, size=size, sha256=sha)


def sha256_file(path: str | Path) -> str:
    """The SHA-256 of a file, hex."""
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for chunk in iter(lambda: f.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def read_checksums(directory: str | Path) -> dict:
    """The checksums recorded by `fetch` in ``directory/checksums.json`` ({} if none)."""
    path = Path(directory) / CHECKSUMS_FILE
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        return {}
    except (OSError, ValueError) as e:
        raise ReplayError(f"{path}: cannot read recorded checksums: {e}") from None
    if not isinstance(data, dict):
        raise ReplayError(f"{path}: cannot read recorded checksums: not a JSON object")
    return data


def check_file(ds, path: Path) -> tuple[str, str]:
    """(sha256, status) of a local copy. With a registered checksum: "verified" or "mismatch".
    Without: CONTENT_CHECKED when `fetch` content-checked this very file (same sha256 as at
    download, ``checksums.json``), "changed" when it differs from it since, else "unknown".
    A checksum seen at download is never taken for a registered one."""
    got = sha256_file(path)
    if ds.sha256:
        return got, "verified" if got == ds.sha256 else "mismatch"
    entry = read_checksums(path.parent).get(path.name)
    if isinstance(entry, dict) and entry.get("content_checked") is True and entry.get("sha256"):
        return got, CONTENT_CHECKED if got == entry["sha256"] else "changed"
    return got, "unknown"


def record_download(dest: Path, ds, sha: str, size: int, src: str, declared: bool = False) -> Path:
    """Keep what was seen of a content-checked download in ``dest/checksums.json`` (atomically).

    ``content_checked`` marks it; it is what the file was at download, not a registered checksum.
    ``declared``: its rows and span matched what the manifest declares.
    """
    path = dest / CHECKSUMS_FILE
    try:
        data = read_checksums(dest)
    except ReplayError:  # our own record file, damaged: start it again
        data = {}
    data[ds.file] = {
        "dataset": ds.id,
        "sha256": sha,
        "size": size,
        "url": src,
        "content_checked": True,
        "declared_checked": declared,
        "registered": False,
        "fetched": datetime.now(timezone.utc).isoformat(timespec="seconds"),
    }
    tmp = None
    try:
        fd, tmp = tempfile.mkstemp(dir=dest, prefix=part_prefix(CHECKSUMS_FILE), suffix=".part")
        with os.fdopen(fd, "w", encoding="utf-8") as f:
            json.dump(data, f, indent=2, sort_keys=True)
            f.write("\n")
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except OSError as e:  # the file is in place; without its record it loads as checksum "unknown"
        raise ReplayError(f"{path}: cannot record the content-checked download of {ds.id}: {e.strerror or e}") from None
    finally:
        if tmp:
            Path(tmp).unlink(missing_ok=True)
    return path


@dataclass(frozen=True)
class Content:
    """What a content check found in a whole file; ``str()`` is its one-line summary."""

    layout: int  # Bohai header layout: 36 or 31 columns
    rows: int  # data rows
    span: float | None  # s, last minus first readable time value (None: no time read)

    def __str__(self) -> str:
        return f"{self.layout}-column Bohai CSV, {self.rows} row{'s' if self.rows != 1 else ''}"


def bohai_csv(path: Path) -> Content:
    """Content check of a Bohai CSV: what it holds when it is a whole table, else ValueError(reason).

    The first line must name every column of one Bohai layout (as the adapter requires),
    every other non-blank line must have as many fields, there must be a data row, and the
    file must end with a line end (a body cut inside its last line has none). The rows and
    the span of the ``time`` column are counted for :func:`declared_mismatch`.
    """
    # lazy: start-up, the Bohai adapter's package imports pandas, pyarrow and pyproj (+290 ms CPU on `replay --help`)
    from replay.adapters.bohai import COLS31, COLS36  # noqa: PLC0415

    with open(path, "rb") as f:
        head = f.read(4096)
        if not head.strip():
            raise ValueError("the body is empty")
        if b"\0" in head or head[:2] == b"\x1f\x8b" or head[:4] == b"PK\x03\x04":
            kind = {b"\x1f\x8b": "a gzip stream", b"PK": "a zip archive"}.get(head[:2], "binary data")
            # hex, not repr: repr's quotes change with the bytes (a gzip header's time stamp)
            raise ValueError(f"{kind}, not a CSV (starts with bytes {head[:8].hex(' ')})")
        f.seek(0)
        first = f.readline(1 << 16)
        try:
            text = first.decode("utf-8-sig")
        except UnicodeDecodeError:
            raise ValueError(f"the first line is not UTF-8 text (starts with {first[:16]!r})") from None
        names = [c.strip() for c in text.strip().split(",")]
        layout = 36 if set(names) >= set(COLS36) else 31 if set(names) >= set(COLS31) else 0
        if not layout:
            raise ValueError(f"the first line is not a Bohai CSV header (starts with {text.strip()[:40]!r})")
        fields, rows, number, last, at = text.count(",") + 1, 0, 1, first, names.index("time")
        times = []
        for number, last in enumerate(f, start=2):
            if not last.strip():
                continue
            cells = last.split(b",")
            if len(cells) != fields:
                raise ValueError(
                    f"line {number} has {len(cells)} fields, the header {fields}: "
                    "the body was cut short or is not a Bohai CSV"
                )
            rows += 1
            times.append(cells[at])
    if not rows:
        raise ValueError("header only, no data rows")
    if not last.endswith(b"\n"):
        raise ValueError(f"the last line ({number}) has no line end: the body was cut short")
    return Content(layout, rows, _span(times))


def _span(cells: list[bytes]) -> float | None:
    """Last minus first finite value of a column's cells (None when fewer than one)."""
    values = []
    for cell in (cells, cells[::-1]):
        for c in cell:
            try:
                v = float(c)
            except ValueError:
                continue
            if v == v and abs(v) != float("inf"):
                values.append(v)
                break
    return values[1] - values[0] if len(values) == 2 else None


SPAN_TOLERANCE = 0.5  # s: listings give a sequence's span rounded to the second


def declares(ds) -> bool:
    """Whether the manifest declares what the whole file holds (``rows``, ``span_s``)."""
    return ds.rows is not None or ds.span_s is not None


def declared_mismatch(ds, content: Content) -> str | None:
    """Why ``content`` is not the file the upstream listing declares (its ``rows`` and its
    ``span_s`` within :data:`SPAN_TOLERANCE`), or None; only what is declared is compared."""
    problems = []
    if ds.rows is not None and content.rows != ds.rows:
        problems.append(f"{content.rows} rows, the upstream listing declares {ds.rows}")
    if ds.span_s is not None and (content.span is None or abs(content.span - ds.span_s) > SPAN_TOLERANCE):
        got = "no readable time" if content.span is None else f"a time span of {content.span:.1f} s"
        problems.append(f"{got}, the upstream listing declares {ds.span_s:g} s")
    return "; ".join(problems) or None


def identical_to(ds, sha: str, directory: Path | None = None) -> str | None:
    """Another sequence whose checksum is ``sha`` (its registered one, or the one recorded at its
    download in ``directory/checksums.json``), named with where that checksum comes from; or None.
    A file with that checksum is that sequence, not ``ds``."""
    for other, (_, _, registered) in REGISTERED.items():
        if registered == sha and other != ds.id:
            return f"{other} (its registered sha256)"
    try:
        recorded = read_checksums(directory) if directory is not None else {}
    except ReplayError:
        recorded = {}
    for entry in recorded.values():
        other = entry.get("dataset") if isinstance(entry, dict) else None
        if other and other != ds.id and entry.get("sha256") == sha:
            return f"{other} (its sha256 recorded at download in {CHECKSUMS_FILE})"
    return None


def check_loaded(ds, path: Path, frame) -> None:
    """The checks of a located file dataset that loads: ``frame.meta`` gets its ``sha256``,
    ``checksum`` status and ``content_checked`` (True: the registered checksum matched, or the
    row count and time span the manifest declares; False: nothing published confirms the file).
    A file byte-identical to another sequence is refused; an edited file (checksum ``mismatch``
    or ``changed``) and one that contradicts the declared rows or span are flagged in the report."""
    sha, status = check_file(ds, path)
    other = None if status == "verified" else identical_to(ds, sha, path.parent)
    if other:
        raise ReplayError(
            f"{path}: this file is byte-identical to {other}, so it is not {ds.id} "
            f"(sha256 {sha}); fetch it again with `replay datasets fetch {ds.id} --force`"
        )
    checked = status == "verified"
    if status in ("mismatch", "changed"):
        expected = ds.sha256 or "the checksum recorded at download"
        frame.report.add(
            "flagged",
            path.name,
            1,
            f"sha256 {sha} differs from {expected}: the file was edited or is "
            "another version; results may not compare with published ones",
        )
    elif not checked and declares(ds) and ds.adapter in CONTENT_CHECKS:
        try:
            why = declared_mismatch(ds, CONTENT_CHECKS[ds.adapter](path))
        except ValueError as e:
            why = str(e)
        checked = why is None
        if why:
            frame.report.add("flagged", path.name, 1, f"not the file the upstream listing declares: {why}")
    frame.meta.update(path=str(path), sha256=sha, checksum=status, content_checked=checked)
    if not checked and (ds.id, sha) not in _NOTED:  # once per file and process
        _NOTED.add((ds.id, sha))
        why = {"mismatch": "its sha256 is not the registered one", "changed": "it was edited since its download"}.get(
            status,
            "it contradicts the rows or span its listing declares"
            if declares(ds)
            else "no registered checksum, no declared rows or span",
        )
        logging.getLogger("replay").info(
            f"{ds.id}: {path} is not confirmed as the published file ({why}): "
            "leaderboard rows on it say content_checked=False"
        )


_NOTED: set = set()


# adapter -> content check of a downloaded file (summary, or ValueError with the reason)
CONTENT_CHECKS = {"bohai-csv": bohai_csv}
