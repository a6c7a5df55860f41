"""Downloading datasets from a loopback HTTP server laid out like the upstream repository.

The server serves a tmp directory holding symlinks (or synthetic files) at the
upstream paths (e.g. ``20220822/0/20220822_0_0.csv``), and
``$REPLAY_DATASET_BASE_URL`` points at it, so URLs are built exactly as for the
real upstream: ``<base>/<upstream_path>``. Hostile answers (truncated, HTML,
slow, redirect loops, ...) are in ``tests/test_hostile_http.py``.
"""
import functools
import http.server
import json
import socket
import threading

import pytest

from replay.data import registry
from replay.adapters.bohai import COLS31, COLS36
from replay.data.checksums import CONTENT_CHECKED, REGISTERED
from replay.data.fetch import download_url, fetch
from replay.util.errors import ReplayError
from hostile import assert_ok, assert_refused, invoke


def bohai_body(rows=3, layout=36, end=b"\r\n") -> bytes:
    """A small synthetic Bohai CSV (header of the layout, ``rows`` numeric rows)."""
    cols = COLS36 if layout == 36 else COLS31
    lines = [",".join(cols).encode()]
    lines += [",".join(f"{0.1 * r + i:.3f}" for i in range(len(cols))).encode() for r in range(rows)]
    return end.join(lines) + end


class QuietHandler(http.server.SimpleHTTPRequestHandler):
    def log_message(self, *args):
        pass


@pytest.fixture
def upstream(tmp_path, monkeypatch):
    """(root dir served over HTTP, base url); REPLAY_DATASET_BASE_URL set to it."""
    root = tmp_path / "upstream"
    root.mkdir()
    handler = functools.partial(QuietHandler, directory=str(root))
    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), handler)
    thread = threading.Thread(target=server.serve_forever, args=(0.05,), daemon=True)
    thread.start()
    base = f"http://127.0.0.1:{server.server_address[1]}"
    monkeypatch.setenv("REPLAY_DATASET_BASE_URL", base)
    monkeypatch.setenv("REPLAY_CACHE_DIR", str(tmp_path / "cache"))
    monkeypatch.delenv("REPLAY_DATA_DIR", raising=False)
    yield root, base
    server.shutdown()
    server.server_close()


def publish(root, ds_id, source=None, data=None):
    """Put a file at the dataset's upstream path: a symlink to ``source`` or ``data`` bytes."""
    path = root / registry.get(ds_id).upstream_path
    path.parent.mkdir(parents=True, exist_ok=True)
    path.unlink(missing_ok=True)
    if source is not None:
        path.symlink_to(source)
    else:
        path.write_bytes(data)
    return path


def leftovers(dest):
    return sorted(p.name for p in dest.iterdir() if p.name.endswith(".part")) if dest.exists() else []


def test_url_building(monkeypatch):
    ds = registry.get("bohai/20220822_0_0")
    monkeypatch.delenv("REPLAY_DATASET_BASE_URL", raising=False)
    assert download_url(ds) == ds.url
    assert download_url(ds, "https://mirror/x.csv") == "https://mirror/x.csv"
    monkeypatch.setenv("REPLAY_DATASET_BASE_URL", "http://127.0.0.1:9/mirror/")
    assert download_url(ds) == "http://127.0.0.1:9/mirror/20220822/0/20220822_0_0.csv"


def test_registered_checksums_and_sizes():
    """The 10 sequences of UPSTREAM_SHA256SUMS carry their checksum and size; the 7 others none."""
    known = {i: ds for i, ds in registry.all_datasets().items() if i.startswith("bohai/")}
    assert len(known) == 17
    registered = sorted(i for i, ds in known.items() if ds.sha256)
    assert registered == sorted(REGISTERED) and len(registered) == 10
    assert all(known[i].size == REGISTERED[i][1] and known[i].sha256 == REGISTERED[i][2] for i in registered)
    assert all(known[i].upstream_path == REGISTERED[i][0] for i in registered)
    assert all(ds.size is None for i, ds in known.items() if i not in REGISTERED)
    # the four not shipped in shared/ are registered too
    assert {"bohai/20220625_0_1", "bohai/20220712_0_1", "bohai/20220719_6_1", "bohai/20230517_0_0"} <= set(registered)


def test_registered_table_is_upstream_sha256sums(bohai_dir):
    """The constants are exactly the shared UPSTREAM_SHA256SUMS (and the six local files match them)."""
    rows = [line.split() for line in (bohai_dir / "UPSTREAM_SHA256SUMS").read_text().splitlines()
            if line.strip() and not line.startswith("#")]
    assert len(rows) == 10
    table = {"bohai/" + path.rsplit("/", 1)[-1][:-4]: (path, int(size), sha) for sha, size, path in rows}
    assert table == REGISTERED
    for f in sorted(bohai_dir.glob("*.csv")):
        path, size, sha = REGISTERED["bohai/" + f.stem]
        assert f.stat().st_size == size and registry.sha256_file(f) == sha


def test_manifest_contradicting_the_registered_checksum_is_refused(tmp_path):
    (tmp_path / "b.toml").write_text('adapter = "bohai-csv"\n[[dataset]]\nid = "bohai/20220822_0_0"\n'
                                     'file = "20220822_0_0.csv"\nsha256 = "' + "0" * 64 + '"\n')
    with pytest.raises(ReplayError, match=r"dataset bohai/20220822_0_0: sha256 0{64} differs from the "
                                          r"registered upstream db16c328"):
        registry.all_datasets(tmp_path)


def test_fetch_verifies_and_second_fetch_is_a_noop(upstream, tmp_path, bohai_dir):
    root, _ = upstream
    served = publish(root, "bohai/20220822_0_0", source=bohai_dir / "20220822_0_0.csv")
    dest = tmp_path / "dest"
    result = fetch("bohai/20220822_0_0", dest)
    assert result.path == dest / "20220822_0_0.csv"
    assert result.verified and result.downloaded and not result.content_checked
    assert result.sha256 == registry.get("bohai/20220822_0_0").sha256
    assert result.path.stat().st_size == 1071327
    assert "size and sha256 verified" in result.message
    assert leftovers(dest) == [] and not (dest / "checksums.json").exists()

    served.unlink()  # a second fetch must not even ask the server
    again = fetch("bohai/20220822_0_0", dest)
    assert not again.downloaded and again.verified and again.path == result.path
    assert "already present" in again.message
    assert registry.locate("bohai/20220822_0_0", dest) == result.path


def test_fetch_defaults_to_the_cache(upstream, tmp_path, bohai_dir):
    root, _ = upstream
    publish(root, "bohai/20220822_0_0", source=bohai_dir / "20220822_0_0.csv")
    result = fetch("bohai/20220822_0_0")
    assert result.path == tmp_path / "cache" / "bohai" / "20220822_0_0.csv"
    assert registry.locate("bohai/20220822_0_0") == result.path


def test_corrupted_download_is_refused(upstream, tmp_path, bohai_dir):
    root, _ = upstream
    data = bytearray((bohai_dir / "20220822_0_0.csv").read_bytes())
    data[5000] ^= 1
    publish(root, "bohai/20220822_0_0", data=bytes(data))
    dest = tmp_path / "dest"
    with pytest.raises(ReplayError) as err:
        fetch("bohai/20220822_0_0", dest)
    msg = str(err.value)
    assert msg.startswith("checksum mismatch for bohai/20220822_0_0: expected db16c328")
    assert "the download was discarded" in msg and "\n" not in msg
    assert list(dest.iterdir()) == []  # neither the final name nor a temp file


def test_mismatching_local_copy_is_replaced(upstream, tmp_path, bohai_dir):
    root, _ = upstream
    publish(root, "bohai/20220822_0_0", source=bohai_dir / "20220822_0_0.csv")
    dest = tmp_path / "dest"
    dest.mkdir()
    (dest / "20220822_0_0.csv").write_text("edited\n")
    result = fetch("bohai/20220822_0_0", dest)
    assert result.downloaded and result.verified and "replaced" in result.message


def test_unregistered_download_is_content_checked_not_registered(upstream, tmp_path):
    root, base = upstream
    body = bohai_body(rows=4)
    publish(root, "bohai/20220822_0_7", data=body)
    dest = tmp_path / "dest"
    result = fetch("bohai/20220822_0_7", dest)
    assert result.downloaded and not result.verified and result.content_checked
    assert result.path.read_bytes() == body
    assert result.sha256 == registry.sha256_file(result.path)
    assert (f"({len(body)} bytes, as announced by the server); checksum not registered upstream; "
            "content-checked: 36-column Bohai CSV, 4 rows; nothing published to check it against: rows using it "
            "say content_checked=false; sha256 " + result.sha256) in result.message
    recorded = json.loads((dest / "checksums.json").read_text())["20220822_0_7.csv"]
    assert recorded["sha256"] == result.sha256 and recorded["size"] == len(body)
    assert recorded["content_checked"] is True and recorded["registered"] is False
    assert recorded["declared_checked"] is False  # the manifest declares no rows nor span of 0_7
    assert recorded["dataset"] == "bohai/20220822_0_7"
    assert recorded["url"] == base + "/20220822/0/20220822_0_7.csv"
    assert leftovers(dest) == []
    ds = registry.get("bohai/20220822_0_7")
    assert ds.sha256 is None  # the checksum seen is not registered
    assert registry.check_file(ds, result.path) == (result.sha256, CONTENT_CHECKED)
    again = fetch("bohai/20220822_0_7", dest)
    assert not again.downloaded and "content-checked: 36-column Bohai CSV, 4 rows" in again.message
    result.path.write_bytes(bohai_body(rows=5))  # edited since: "changed", not content-checked
    assert registry.check_file(ds, result.path)[1] == "changed"


def test_a_31_column_file_passes_the_content_check(upstream, tmp_path):
    root, _ = upstream
    publish(root, "bohai/20220822_0_8", data=bohai_body(rows=2, layout=31, end=b"\n"))
    result = fetch("bohai/20220822_0_8", tmp_path / "dest")
    assert result.content_checked and "31-column Bohai CSV, 2 rows" in result.message


def test_old_record_without_content_check_is_not_trusted(tmp_path):
    """A checksums.json entry written before content checks existed does not vouch for the file."""
    (tmp_path / "20220822_0_7.csv").write_bytes(bohai_body())
    sha = registry.sha256_file(tmp_path / "20220822_0_7.csv")
    (tmp_path / "checksums.json").write_text(json.dumps({"20220822_0_7.csv": {"sha256": sha}}))
    assert registry.check_file(registry.get("bohai/20220822_0_7"), tmp_path / "20220822_0_7.csv") == (sha, "unknown")


def test_present_file_failing_the_content_check_is_replaced(upstream, tmp_path):
    root, _ = upstream
    publish(root, "bohai/20220822_0_7", data=bohai_body(rows=2))
    dest = tmp_path / "dest"
    dest.mkdir()
    (dest / "20220822_0_7.csv").write_bytes(b"<html>an error page stored by an old version</html>\n")
    result = fetch("bohai/20220822_0_7", dest)
    assert result.downloaded and result.path.read_bytes() == bohai_body(rows=2)
    assert "the local copy failed the content check (the first line is not a Bohai CSV header" in result.message


def test_force_replaces_atomically(upstream, tmp_path):
    root, _ = upstream
    dest = tmp_path / "dest"
    publish(root, "bohai/20220822_0_7", data=bohai_body(rows=2))
    first = fetch("bohai/20220822_0_7", dest)
    publish(root, "bohai/20220822_0_7", data=bohai_body(rows=6))
    assert not fetch("bohai/20220822_0_7", dest).downloaded  # present and fine: kept
    assert first.path.read_bytes() == bohai_body(rows=2)
    forced = fetch("bohai/20220822_0_7", dest, force=True)
    assert forced.downloaded and "replaced (force)" in forced.message
    assert first.path.read_bytes() == bohai_body(rows=6)
    assert json.loads((dest / "checksums.json").read_text())["20220822_0_7.csv"]["sha256"] == forced.sha256
    # a forced download that fails leaves the copy that was there
    publish(root, "bohai/20220822_0_7", data=bohai_body(rows=6)[:-40])
    with pytest.raises(ReplayError, match="the content check failed"):
        fetch("bohai/20220822_0_7", dest, force=True)
    assert first.path.read_bytes() == bohai_body(rows=6) and leftovers(dest) == []


def test_cli_force_and_info(upstream, tmp_path):
    root, _ = upstream
    dest = tmp_path / "dest"
    publish(root, "bohai/20220822_0_7", data=bohai_body(rows=2))
    assert "downloaded to" in assert_ok(["datasets", "fetch", "bohai/20220822_0_7", "--dest", dest]).stdout
    publish(root, "bohai/20220822_0_7", data=bohai_body(rows=7))
    out = assert_ok(["datasets", "fetch", "bohai/20220822_0_7", "--dest", dest, "--force"]).stdout
    assert "content-checked: 36-column Bohai CSV, 7 rows" in out and "replaced (force)" in out
    info = assert_ok(["datasets", "info", "bohai/20220822_0_7", "--data-dir", tmp_path / "nowhere"]).stdout
    assert "checksum:       not registered upstream (a download is accepted only after a content check)" in info
    info = assert_ok(["datasets", "info", "bohai/20220822_0_0", "--data-dir", tmp_path / "nowhere"]).stdout
    assert "size:           1071327" in info and "checksum:       not registered" not in info


def test_http_404_is_one_line(upstream, tmp_path):
    dest = tmp_path / "dest"
    with pytest.raises(ReplayError) as err:
        fetch("bohai/20220822_0_8", dest)
    msg = str(err.value)
    assert msg.startswith("cannot download bohai/20220822_0_8: HTTP 404")
    assert "(url http://127.0.0.1:" in msg and "\n" not in msg
    assert list(dest.iterdir()) == []


def test_server_down_is_one_line(tmp_path, monkeypatch):
    sock = socket.socket()
    sock.bind(("127.0.0.1", 0))
    port = sock.getsockname()[1]
    sock.close()  # nothing listens on this port now
    monkeypatch.setenv("REPLAY_DATASET_BASE_URL", f"http://127.0.0.1:{port}")
    dest = tmp_path / "dest"
    with pytest.raises(ReplayError) as err:
        fetch("bohai/20220822_0_0", dest, timeout=5)
    msg = str(err.value)
    assert msg.startswith("cannot download bohai/20220822_0_0: ")
    assert "refused" in msg.lower() and f"127.0.0.1:{port}" in msg and "\n" not in msg
    assert leftovers(dest) == [] and not (dest / "20220822_0_0.csv").exists()


def test_silent_server_times_out(tmp_path, monkeypatch):
    with socket.socket() as sock:  # accepts connections (backlog) but never answers
        sock.bind(("127.0.0.1", 0))
        sock.listen()
        monkeypatch.setenv("REPLAY_DATASET_BASE_URL", f"http://127.0.0.1:{sock.getsockname()[1]}")
        with pytest.raises(ReplayError, match=r"^cannot download bohai/20220822_0_0: timed out after 0.2 s \(url "):
            fetch("bohai/20220822_0_0", tmp_path, timeout=0.2)
    assert list(tmp_path.iterdir()) == []


def test_deadline_and_timeout_are_checked(tmp_path):
    for bad in (0, -1, float("nan"), float("inf"), True):
        with pytest.raises(ReplayError, match=r"^download deadline must be a positive number of seconds"):
            fetch("bohai/20220822_0_0", tmp_path, deadline=bad)
    with pytest.raises(ReplayError, match=r"^download timeout must be"):
        fetch("bohai/20220822_0_0", tmp_path, timeout=0)


def test_sims_are_not_downloaded(tmp_path):
    with pytest.raises(ReplayError, match="generated on demand"):
        fetch("sim/auv-sonar", tmp_path)


def test_cli_fetch(upstream, tmp_path):
    root, _ = upstream
    publish(root, "bohai/20220822_0_7", data=bohai_body(rows=1))
    publish(root, "bohai/20220822_0_8", data=bohai_body(rows=2))
    dest = tmp_path / "dest"
    result = assert_ok(["datasets", "fetch", "bohai/20220822_0_7", "bohai/20220822_0_8", "--dest", dest])
    assert result.stdout.count("checksum not registered upstream; content-checked") == 2
    assert sorted(p.name for p in dest.iterdir()) == ["20220822_0_7.csv", "20220822_0_8.csv", "checksums.json"]
    assert_refused(["datasets", "fetch", "bohai/20220822_0_1", "--dest", dest],
                   r"^replay: error: cannot download bohai/20220822_0_1: HTTP 404")
    # several: each failure on stdout, one summary line on stderr
    res = invoke(["datasets", "fetch", "bohai/20220822_0_7", "bohai/20220822_0_1", "--dest", dest])
    assert res.exit_code == 2 and "failed: cannot download bohai/20220822_0_1: HTTP 404" in res.stdout
    assert res.stderr.strip() == "replay: error: 1 of 2 downloads failed: bohai/20220822_0_1"
    assert_refused(["datasets", "fetch"], r"--all")


def test_info_and_manifest_say_not_registered_content_checked(upstream, tmp_path, bohai_dir):
    """A content-checked download loads with checksum "not registered upstream (content-checked)",
    and content_checked False: nothing published (no checksum, no declared rows or span) confirms it."""
    root, _ = upstream
    lines = (bohai_dir / "20220822_0_0.csv").read_bytes().splitlines(keepends=True)
    publish(root, "bohai/20220822_0_7", data=b"".join(lines[:2001]))  # 0_0's first 2000 rows as 0_7
    dest = tmp_path / "dest"
    fetch("bohai/20220822_0_7", dest)
    frame = registry.load_frame("bohai/20220822_0_7", data_dir=dest, first=10)
    assert frame.meta["checksum"] == "not registered upstream (content-checked)"
    assert frame.meta["content_checked"] is False
    assert not [e for e in frame.report.find("flagged") if e.what == "20220822_0_7.csv"]  # no checksum flag
    info = assert_ok(["datasets", "info", "bohai/20220822_0_7", "--data-dir", dest]).stdout
    assert "  checksum: not registered upstream (content-checked)" in info.splitlines()
    assert "  content_checked: False" in info.splitlines()


@pytest.mark.slow
def test_kill_during_download_leaves_no_final_file(tmp_path):
    """kill -9 while the body is arriving: the final name never holds the partial file; a later
    fetch completes it."""
    import os
    import signal
    import subprocess
    import sys
    import time

    body = bohai_body(rows=3)
    state = {"slow": True, "sent": 0}

    class Slow(http.server.BaseHTTPRequestHandler):
        def do_GET(self):
            self.send_response(200)
            self.send_header("Content-Length", str(len(body)))
            self.end_headers()
            try:
                for i in range(len(body)):
                    self.wfile.write(body[i:i + 1])
                    self.wfile.flush()
                    state["sent"] += 1
                    time.sleep(0.2 if state["slow"] else 0)
            except OSError:
                pass

        def log_message(self, *args):
            pass

    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), Slow)
    threading.Thread(target=server.serve_forever, args=(0.05,), daemon=True).start()
    dest = tmp_path / "dest"
    env = dict(os.environ, REPLAY_DATASET_BASE_URL=f"http://127.0.0.1:{server.server_address[1]}")
    proc = subprocess.Popen([sys.executable, "-m", "replay.cli", "datasets", "fetch", "bohai/20220822_0_7",
                             "--dest", str(dest)], env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline and not (leftovers(dest) and state["sent"] >= 5):
            time.sleep(0.05)
        assert leftovers(dest) and state["sent"] >= 5, "the download never started"
    finally:
        proc.send_signal(signal.SIGKILL)
        proc.wait()
    assert not (dest / "20220822_0_7.csv").exists() and not (dest / "checksums.json").exists()
    state["slow"] = False
    result = fetch("bohai/20220822_0_7", dest, url=env["REPLAY_DATASET_BASE_URL"] + "/x.csv")
    assert result.path.read_bytes() == body
    assert leftovers(dest) == [] and "; removed 1 partial file of interrupted downloads (" in result.message
    server.shutdown()
    server.server_close()


def test_fetch_progress_counts_kilobytes_to_the_size(upstream, tmp_path, bohai_dir):
    """`replay datasets fetch` shows progress in kilobytes of the known size; it ends at the size."""
    from replay.util.progress import Progress

    root, _ = upstream
    publish(root, "bohai/20220822_0_0", source=bohai_dir / "20220822_0_0.csv")
    seen = []

    class Spy(Progress):
        def update(self, n=1, failed=0, weight=None):
            seen.append(n)
            super().update(n, failed, weight)

    spy = Spy(0, quiet=True, unit="kilobyte")
    fetch("bohai/20220822_0_0", tmp_path / "dest", progress=spy)
    assert spy.total == -(-1071327 // 1024) == 1047
    assert sum(seen) == 1047 and all(n >= 0 for n in seen)  # whole kilobytes, then the last partial one
    res = invoke(["datasets", "fetch", "bohai/20220822_0_0", "--dest", tmp_path / "d2", "-q"])
    assert res.exit_code == 0 and res.stderr == ""
