"""Download file datasets, verified and atomically.

The file is streamed into a temporary ``.<file>.*.part`` in the destination
directory and hashed while it is written. When the manifest knows the sha256,
a mismatch discards the download; otherwise the observed sha256 is recorded in
``checksums.json`` beside the file. Only a complete, checked file is moved
(``os.replace``) to its final name, so a final name never holds a partial file.

The download URL is the manifest's ``url``, unless ``url=`` is given or
``$REPLAY_DATASET_BASE_URL`` is set: then it is ``<base>/<upstream_path>``
(a mirror, or a test server, laid out like the upstream repository).
"""
from __future__ import annotations

import hashlib
import http.client
import json
import os
import tempfile
import urllib.error
import urllib.parse
import urllib.request
from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path

import replay
from replay import registry
from replay.util.errors import ReplayError
from replay.registry import CHECKSUMS_FILE, Dataset


@dataclass
class FetchResult:
    path: Path
    sha256: str
    verified: bool  # matched the manifest's checksum
    downloaded: bool = True  # False when the file was already in place
    message: str = ""  # one line for the user


def download_url(ds: Dataset, url: str | None = None) -> str:
    """``url``, else ``$REPLAY_DATASET_BASE_URL/<upstream_path>``, else the manifest url."""
    if url:
        return url
    base = os.environ.get("REPLAY_DATASET_BASE_URL")
    if base:
        return base.rstrip("/") + "/" + urllib.parse.quote(ds.upstream_path or ds.file)
    if not ds.url:
        raise ReplayError(f"dataset {ds.id} has no download url in {ds.manifest}")
    return ds.url


def default_dest(ds: Dataset) -> Path:
    """Where `fetch` puts a dataset by default: <user cache>/<prefix>/."""
    return registry.cache_dir() / ds.namespace


def fetch(ds: Dataset | str, dest_dir: str | Path | None = None, *, url: str | None = None,
          timeout: float = 30) -> FetchResult:
    """Make sure ``dest_dir/<file>`` holds the dataset, downloading it if needed."""
    ds = registry.get(ds) if isinstance(ds, str) else ds
    if ds.kind != "file":
        raise ReplayError(f"{ds.id} is generated on demand; there is nothing to download")
    dest = Path(dest_dir).expanduser() if dest_dir else default_dest(ds)
    target = dest / ds.file

    note = ""
    if target.is_file():
        sha, status = registry.check_file(ds, target)
        if status != "mismatch":
            extra = {"verified": "checksum verified", "unknown": "checksum not known upstream",
                     "recorded": "matches the checksum recorded at download",
                     "changed": "differs from the checksum recorded at download"}[status]
            return FetchResult(target, sha, status == "verified", False,
                               f"{ds.id}: already present at {target} ({extra})")
        note = "; the local copy did not match the manifest checksum and was replaced"

    src = download_url(ds, url)
    if urllib.parse.urlsplit(src).scheme not in ("https", "http"):
        raise ReplayError(f"cannot download {ds.id}: only http(s) URLs are supported (url {src})")
    try:
        dest.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise ReplayError(f"cannot create {dest}: {e.strerror or e}") from None

    sha = _download(ds, src, dest, target, timeout)
    if ds.sha256:
        return FetchResult(target, sha, True, True, f"{ds.id}: downloaded to {target}, sha256 verified{note}")
    record = _record_checksum(dest, ds, sha, src)
    return FetchResult(target, sha, False, True,
                       f"{ds.id}: downloaded to {target}; checksum not known upstream; "
                       f"recorded sha256 {sha} in {record}")


def _download(ds: Dataset, src: str, dest: Path, target: Path, timeout: float) -> str:
    """Stream ``src`` into a temp file in ``dest``, check it, move it to ``target``."""
    fd, tmp = tempfile.mkstemp(dir=dest, prefix=f".{ds.file}.", suffix=".part")
    try:
        h = hashlib.sha256()
        with os.fdopen(fd, "wb") as out:
            request = urllib.request.Request(src, headers={"User-Agent": f"replay-nav/{replay.__version__}"})
            try:
                with urllib.request.urlopen(request, timeout=timeout) as resp:
                    expected = resp.headers.get("Content-Length")
                    size = 0
                    while chunk := resp.read(1 << 16):
                        out.write(chunk)
                        h.update(chunk)
                        size += len(chunk)
                if expected is not None and size != int(expected):
                    raise ReplayError(f"cannot download {ds.id}: connection closed after {size} of "
                                      f"{expected} bytes (url {src})")
                out.flush()
                os.fsync(out.fileno())
            except (OSError, http.client.HTTPException, ValueError) as e:
                raise ReplayError(f"cannot download {ds.id}: {_reason(e, timeout)} (url {src})") from None
        sha = h.hexdigest()
        if ds.sha256 and sha != ds.sha256:
            raise ReplayError(f"checksum mismatch for {ds.id}: expected {ds.sha256}, got {sha}; "
                              f"the download was discarded (url {src})")
        os.replace(tmp, target)
        return sha
    finally:
        Path(tmp).unlink(missing_ok=True)  # gone already after a successful replace


def _reason(e: Exception, timeout: float) -> str:
    """A short one-line reason for a network failure."""
    if isinstance(e, urllib.error.HTTPError):
        return f"HTTP {e.code} {e.reason}"
    if isinstance(e, urllib.error.URLError):
        if not isinstance(e.reason, BaseException):
            return " ".join(str(e.reason).split())
        e = e.reason
    if isinstance(e, TimeoutError):
        return f"timed out after {timeout:g} s"
    text = getattr(e, "strerror", None) or str(e) or type(e).__name__
    return " ".join(str(text).split())


def _record_checksum(dest: Path, ds: Dataset, sha: str, src: str) -> Path:
    """Add the observed checksum to ``dest/checksums.json`` (written atomically)."""
    path = dest / CHECKSUMS_FILE
    data = registry.read_checksums(dest)
    data[ds.file] = {"dataset": ds.id, "sha256": sha, "url": src,
                     "fetched": datetime.now(timezone.utc).isoformat(timespec="seconds")}
    fd, tmp = tempfile.mkstemp(dir=dest, prefix=f".{CHECKSUMS_FILE}.", suffix=".part")
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as f:
            json.dump(data, f, indent=2, sort_keys=True)
            f.write("\n")
        os.replace(tmp, path)
    finally:
        Path(tmp).unlink(missing_ok=True)
    return path
