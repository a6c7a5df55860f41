"""Download file datasets: bounded in time, checked, written atomically.

The file is streamed into a temporary ``.<file>.<pid>@<host>.*.part`` in the destination
directory and hashed while it is written. Only a file that passed every check is moved
(``os.replace``) to its final name, so a final name never holds a partial or unchecked file,
and a failed download leaves no temporary file (and an existing copy untouched, also with
``force``); those of killed downloads are removed by the next download into the directory
(:func:`replay.util.downloads.remove_stale_parts`), and counted in its message.

Checks, in order; the first that fails refuses the download in one line naming
the dataset and the URL:

* the answer: HTTP 200 after at most ``MAX_REDIRECTS`` redirects (no loop, no
  https -> http), no ``Content-Encoding`` (none is asked for), not an HTML page,
  not empty, the announced ``Content-Length`` equal to the registered size;
* the body: as many bytes as ``Content-Length`` announced;
* with a registered checksum (``replay/data/checksums.py``): the size and the sha256;
* a sha256 that is another sequence's (registered, or recorded at its download): refused;
* without one: the adapter's content check (``checksums.CONTENT_CHECKS``; a Bohai CSV
  needs a header of one of the two Bohai layouts, the same number of fields on
  every line and a final line end), then the row count and time span the manifest
  declares (``rows``, ``span_s``), where it declares them. A dataset whose adapter has
  no content check is not downloaded at all. The sha256 seen is kept in ``checksums.json``
  beside the file, never as a registered checksum;
* a body whose length nothing confirms is never stored: without a registered size or checksum,
  a declared ``size``, ``rows`` or ``span_s``, and a ``Content-Length`` from the server, a body
  cut exactly at a line end would pass every check above, so it is refused (declare ``rows`` and
  ``span_s`` in the manifest, or fetch from a server that announces the size). A body whose
  announced length is confirmed but with nothing declared is stored, ``content_checked`` false
  in every leaderboard row that uses it (``checksums.check_loaded``).

Time: ``timeout`` bounds each wait for the server (connect, each read), and
``deadline`` the whole download, redirects included: when it passes, the open
socket is shut down, so a server dripping one byte every few seconds cannot hold
it longer (only the DNS look-up is not covered).

The download URL is the manifest's ``url``, unless ``url=`` is given or
``$REPLAY_DATASET_BASE_URL`` is set: then it is ``<base>/<upstream_path>``
(a mirror, or a test server, laid out like the upstream repository). An
``http(s)_proxy`` from the environment is used (CONNECT for https).
"""

from __future__ import annotations

import errno
import hashlib
import http.client
import os
import socket
import ssl
import tempfile
import urllib.parse
import urllib.request
from dataclasses import dataclass
from pathlib import Path

from replay.data import registry
from replay.data.checksums import CONTENT_CHECKS, declared_mismatch, declares, identical_to, record_download
from replay.data.registry import Dataset
from replay.util.downloads import Deadline, check_url, network_reason, part_prefix, printable, remove_stale_parts
from replay.util.errors import ReplayError
from replay.util.files import check_writable
from replay.util.staging import check_space
from replay.util.version import __version__

DEFAULT_TIMEOUT = 30.0  # s of silence from the server (connect, each read)
DEFAULT_DEADLINE = 300.0  # s for a whole download (the Bohai files are 0.3-4 MB)
MAX_REDIRECTS = 5
LOCAL_ERRNOS = {errno.ENOSPC, errno.EDQUOT, errno.EFBIG, errno.EROFS, errno.EIO}


@dataclass
class FetchResult:
    path: Path
    sha256: str
    verified: bool  # matched the registered checksum
    downloaded: bool = True  # False when the file was already in place
    message: str = ""  # one line for the user
    content_checked: bool = False  # no registered checksum; passed the content check


def download_url(ds: Dataset, url: str | None = None) -> str:
    """``url``, else ``$REPLAY_DATASET_BASE_URL/<upstream_path>``, else the manifest url; an
    absolute http(s) URL, else refused in one line naming where it came from."""
    if url:
        return check_url(url, "download url")
    base = os.environ.get("REPLAY_DATASET_BASE_URL")
    if base:
        check_url(base, "$REPLAY_DATASET_BASE_URL")
        return base.rstrip("/") + "/" + urllib.parse.quote(ds.upstream_path or ds.file)
    if not ds.url:
        raise ReplayError(f"dataset {ds.id} has no download url in {ds.manifest}")
    return check_url(ds.url, f"{ds.manifest}: dataset {ds.id}: url")


def default_dest(ds: Dataset) -> Path:
    """Where `fetch` puts a dataset by default: <user cache>/<prefix>/."""
    return registry.cache_dir() / ds.namespace


def fetch(
    ds: Dataset | str,
    dest_dir: str | Path | None = None,
    *,
    url: str | None = None,
    timeout: float = DEFAULT_TIMEOUT,
    deadline: float = DEFAULT_DEADLINE,
    force: bool = False,
    progress=None,
) -> FetchResult:
    """Make sure ``dest_dir/<file>`` holds the dataset, downloading it if needed.

    ``force`` downloads again and replaces the copy in place (only once the new one
    passed every check). ``timeout``: seconds of silence allowed; ``deadline``:
    seconds for the whole download. ``progress``: a :class:`replay.util.progress.Progress`
    advanced in kB received, when the size is known (announced or registered).
    """
    ds = registry.get(ds) if isinstance(ds, str) else ds
    if ds.kind != "file":
        raise ReplayError(f"{ds.id} is generated on demand; there is nothing to download")
    check = None if ds.sha256 else CONTENT_CHECKS.get(ds.adapter)
    if not ds.sha256 and check is None:
        raise ReplayError(
            f"cannot download {ds.id}: it has no registered checksum and its adapter "
            f"{ds.adapter} has no content check, so nothing could confirm the download"
        )
    for name, value in (("timeout", timeout), ("deadline", deadline)):
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not 0 < value < float("inf"):
            raise ReplayError(f"download {name} must be a positive number of seconds (got {value!r})")
    dest = Path(dest_dir).expanduser() if dest_dir else default_dest(ds)
    target = dest / ds.file

    note = ""
    if target.is_file():
        if force:
            note = "; the copy that was there was replaced (force)"
        else:
            present = _present(ds, target, check)
            if isinstance(present, FetchResult):
                return present
            note = present

    src = download_url(ds, url)
    if urllib.parse.urlsplit(src).scheme not in ("https", "http"):
        raise ReplayError(f"cannot download {ds.id}: only http(s) URLs are supported (url {src})")
    what = "download destination" + (
        f" (from {registry.cache_variable()})" if not dest_dir and registry.cache_variable() else ""
    )
    check_writable(dest, what)
    try:
        dest.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise ReplayError(f"cannot create {dest}: {e.strerror or e}") from None
    stale, freed = remove_stale_parts(dest)  # .part files of downloads whose process is gone
    if stale:
        note += f"; removed {stale} partial file{'s' if stale != 1 else ''} of interrupted downloads ({freed} bytes)"
    check_space(dest, what, need=ds.size)  # after the stale files are gone

    sha, size, announced, summary = _download(ds, src, dest, target, timeout, deadline, check, progress)
    if ds.sha256:
        return FetchResult(target, sha, True, True, f"{ds.id}: downloaded to {target}, size and sha256 verified{note}")
    record = record_download(dest, ds, sha, size, src, declared=declares(ds))
    told = "as announced by the server" if announced else "no size announced by the server"
    how = (
        "rows and time span as the upstream listing declares"
        if declares(ds)
        else "nothing published to check it against: rows using it say content_checked=false"
    )
    return FetchResult(
        target,
        sha,
        False,
        True,
        f"{ds.id}: downloaded to {target} ({size} bytes, {told}); checksum not registered "
        f"upstream; content-checked: {summary}; {how}; sha256 {sha} kept in {record}{note}",
        content_checked=True,
    )


def _present(ds: Dataset, target: Path, check) -> FetchResult | str:
    """A result when the copy at ``target`` is fine, else the note saying why it is replaced."""
    if ds.sha256:
        sha, status = registry.check_file(ds, target)
        if status == "verified":
            return FetchResult(target, sha, True, False, f"{ds.id}: already present at {target} (sha256 verified)")
        return "; the local copy did not match the registered checksum and was replaced"
    try:
        summary = check(target)
        sha, status = registry.check_file(ds, target)
        why = declared_mismatch(ds, summary) or identical_to(ds, sha, target.parent)
    except (ValueError, OSError) as e:
        return f"; the local copy failed the content check ({e}) and was replaced"
    if why:
        return f"; the local copy was not {ds.id} ({why}) and was replaced"
    how = {
        registry.CONTENT_CHECKED: "the file downloaded and content-checked",
        "changed": "passes the content check but differs from the file downloaded",
    }.get(status, "passes the content check")
    return FetchResult(
        target,
        sha,
        False,
        False,
        f"{ds.id}: already present at {target} (checksum not registered upstream; {how}: {summary})",
        content_checked=True,
    )


class _TLS(http.client.HTTPSConnection):
    """HTTPS whose TLS socket is put under the deadline before its handshake (wrapping a
    socket detaches it, so the plain socket watched by ``_create_connection`` no longer
    reaches the connection once it is wrapped)."""

    def __init__(self, host, port, *, timeout, clock, tls_host):
        self._tls, self._clock, self._tls_host = ssl.create_default_context(), clock, tls_host
        super().__init__(host, port, timeout=timeout, context=self._tls)

    def connect(self):
        http.client.HTTPConnection.connect(self)  # TCP (and the proxy tunnel), plain socket watched
        self.sock = self._tls.wrap_socket(self.sock, server_hostname=self._tls_host, do_handshake_on_connect=False)
        self._clock.watch(self.sock)
        self.sock.do_handshake()


def _connect(parts, clock: Deadline, timeout: float) -> tuple[http.client.HTTPConnection, str]:
    """A connection for ``parts`` (through the environment's proxy, if any) and the request target;
    every socket it opens is under the deadline."""
    host, port = parts.hostname, parts.port
    path = (parts.path or "/") + (f"?{parts.query}" if parts.query else "")
    proxy = None if urllib.request.proxy_bypass(host) else urllib.request.getproxies().get(parts.scheme)
    if proxy:
        p = urllib.parse.urlsplit(proxy if "://" in proxy else f"http://{proxy}")
        host, port, path = p.hostname, p.port or 80, (path if parts.scheme == "https" else parts.geturl())
    if parts.scheme == "https":
        conn = _TLS(host, port, timeout=timeout, clock=clock, tls_host=parts.hostname)
        if proxy:
            conn.set_tunnel(parts.hostname, parts.port)
    else:
        conn = http.client.HTTPConnection(host, port, timeout=timeout)

    def create(address, wait=None, source=None):
        sock = socket.create_connection(address, min(wait or timeout, clock.left()), source)
        sock.settimeout(wait or timeout)  # the connect was bounded by the deadline; now silence only
        clock.watch(sock)
        return sock

    conn._create_connection = create
    return conn, path


def _open(src: str, clock: Deadline, timeout: float, fail):
    """(response, connection) of a 200 answer for ``src``, following redirects."""
    url, seen = src, [src]
    while True:
        try:
            parts = urllib.parse.urlsplit(url)
            parts.port  # noqa: B018 — a port out of range raises ValueError
        except ValueError as e:
            fail(f"redirected to {url}, which is not a valid URL ({e})")
        if parts.scheme not in ("http", "https") or not parts.hostname:
            fail(f"redirected to {url}, which is not an http(s) URL")
        conn, path = _connect(parts, clock, timeout)
        try:
            conn.request(
                "GET", path, headers={"User-Agent": f"replay-nav/{__version__}", "Accept-Encoding": "identity"}
            )
            resp = conn.getresponse()
        except BaseException:
            conn.close()
            raise
        if resp.status not in (301, 302, 303, 307, 308):
            if resp.status != 200:
                conn.close()
                fail(f"HTTP {resp.status} {' '.join(str(resp.reason).split())}".rstrip())
            return resp, conn
        location = (resp.getheader("Location") or "").strip()
        conn.close()
        if not location:
            fail(f"HTTP {resp.status} redirect without a Location")
        try:
            nxt = urllib.parse.urljoin(url, location)
        except ValueError as e:
            fail(f"redirected to {location}, which is not a valid URL ({e})")
        if nxt in seen:
            fail(f"redirect loop: back to {nxt} at redirect {len(seen)}")
        if len(seen) > MAX_REDIRECTS:
            fail(f"more than {MAX_REDIRECTS} redirects")
        if parts.scheme == "https" and not nxt.startswith("https:"):
            fail(f"redirected from https to {nxt}")
        seen.append(nxt)
        url = nxt


def _check_answer(ds: Dataset, resp, fail) -> int | None:
    """Refuse an answer that cannot be the file from its headers; the announced size or None."""
    encoding = (resp.getheader("Content-Encoding") or "identity").strip().lower()
    if encoding != "identity":
        fail(f"the server sent {encoding}-encoded content, which was not asked for")
    ctype = (resp.getheader("Content-Type") or "").split(";")[0].strip().lower()
    if ctype in ("text/html", "application/xhtml+xml"):
        fail(f"the server sent an HTML page (Content-Type {ctype}), not the data file")
    announced = resp.length  # None when absent, invalid or chunked
    if announced == 0:
        fail("the server sent an empty body (Content-Length 0)")
    if ds.size and announced is not None and announced != ds.size:
        fail(f"the server announces {announced} bytes, the registered size is {ds.size}")
    return announced


def _download(ds: Dataset, src: str, dest: Path, target: Path, timeout: float, deadline: float, check, progress=None):
    """Stream ``src`` into a temp file in ``dest``, check it, move it to ``target``.

    Returns (sha256, size, whether the server announced the size, content summary).
    """

    def fail(reason):  # the reason may quote the server: made printable, bounded
        raise ReplayError(f"cannot download {ds.id}: {printable(reason, 300)} (url {printable(src, 300)})")

    try:
        fd, tmp = tempfile.mkstemp(dir=dest, prefix=part_prefix(ds.file), suffix=".part")
    except OSError as e:
        raise ReplayError(f"cannot write into {dest}: {e.strerror or e}") from None
    clock = Deadline(deadline)
    try:
        h, size = hashlib.sha256(), 0
        with os.fdopen(fd, "wb") as out:
            try:
                resp, conn = _open(src, clock, timeout, fail)
                try:
                    announced = _check_answer(ds, resp, fail)
                    total = announced or ds.size
                    kb = -(-total // 1024) if total else 0
                    if progress is not None and total:
                        progress.start(kb)
                    while chunk := resp.read1(1 << 16):
                        out.write(chunk)
                        h.update(chunk)
                        done = size // 1024
                        size += len(chunk)
                        if ds.size and size > ds.size:
                            fail(f"the server sent more than the registered size of {ds.size} bytes")
                        if progress is not None and total:  # 100 % only once every check passed
                            progress.update(min(size // 1024, kb - 1) - min(done, kb - 1))
                finally:
                    conn.close()
                if clock.passed:
                    raise TimeoutError
                out.flush()
                os.fsync(out.fileno())
            except (OSError, http.client.HTTPException, ValueError) as e:
                if getattr(e, "errno", None) in LOCAL_ERRNOS:  # writing, not the network
                    raise ReplayError(f"cannot write {target}: {e.strerror}; the download was discarded") from None
                if clock.passed:
                    fail(f"not complete within the deadline of {deadline:g} s ({size} bytes received)")
                fail(network_reason(e, timeout))
            finally:
                clock.cancel()
        if announced is not None and size != announced:
            fail(f"connection closed after {size} of {announced} bytes")
        if size == 0:
            fail("the server sent an empty body")
        if ds.size and size != ds.size:
            fail(f"got {size} bytes, the registered size is {ds.size}")
        sha = h.hexdigest()
        other = None if sha == ds.sha256 else identical_to(ds, sha, dest)
        if ds.sha256 and sha != ds.sha256:
            raise ReplayError(
                f"checksum mismatch for {ds.id}: expected {ds.sha256}, got {sha}"
                f"{f', the checksum of {other}' if other else ''}; the download was discarded "
                f"(url {printable(src, 300)})"
            )
        if other:
            fail(f"the body is byte-identical to {other}, not {ds.id}; the download was discarded")
        summary = ""
        if check is not None:
            try:
                summary = check(Path(tmp))
                why = declared_mismatch(ds, summary)
            except ValueError as e:
                fail(f"the content check failed: {e}; the download was discarded")
            if why:
                fail(f"the body holds {why}: cut short or another file; the download was discarded")
        if not (ds.sha256 or ds.size or declares(ds) or announced is not None):
            fail(
                f"the server announced no size and {ds.manifest} declares no size, rows or span_s for {ds.id}: "
                "a body cut at a line end could not be told from the whole file; the download was discarded "
                "(declare rows and span_s, or use a server that sends Content-Length)"
            )
        try:
            os.replace(tmp, target)
        except OSError as e:
            raise ReplayError(f"cannot put the download at {target}: {e.strerror or e}") from None
        if progress is not None and total:
            progress.update(kb - min(size // 1024, kb - 1))
        return sha, size, announced is not None, summary
    finally:
        clock.cancel()
        Path(tmp).unlink(missing_ok=True)  # gone already after a successful replace
