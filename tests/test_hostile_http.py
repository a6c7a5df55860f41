"""Hostile HTTP answers to `replay datasets fetch`: each is refused in one line, and nothing
reaches the final file name (nor is a temporary file left behind).

A loopback server (http.server in a thread on 127.0.0.1, port 0) answers each
upstream path with a scripted behaviour: truncated bodies (with and without a
Content-Length), HTML with 200, wrong checksum or size, HTTP errors, a slow drip
past the deadline, redirect loops, empty bodies, gzip garbage. Datasets with a
registered checksum (bohai/20220822_0_0, 1071327 bytes) and without one
(bohai/20220822_0_7, content-checked) are both exercised.
"""
import gzip
import hashlib
import http.server
import socket
import threading
import time

import pytest
from hostile import assert_refused, register

from replay.adapters.bohai import COLS36

REG, REG_SIZE = "bohai/20220822_0_0", 1071327  # registered checksum and size
UNREG = "bohai/20220822_0_7"  # not registered upstream: content-checked
PATHS = {REG: "/20220822/0/20220822_0_0.csv", UNREG: "/20220822/0/20220822_0_7.csv"}


def csv_body(rows=5) -> bytes:
    """A synthetic 36-column Bohai CSV."""
    lines = [",".join(COLS36)] + [",".join(f"{r + 0.01 * i:.3f}" for i in range(36)) for r in range(rows)]
    return ("\r\n".join(lines) + "\r\n").encode()


HTML = b"<!DOCTYPE html>\n<html><head><title>Sign in</title></head><body>Please log in</body></html>\n"


class Scripted(http.server.BaseHTTPRequestHandler):
    """HTTP/1.0 handler: ``server.routes[path](handler)`` writes the answer (close-delimited
    unless it sends a Content-Length)."""

    def do_GET(self):
        route = self.server.routes.get(self.path)
        if route is None:
            self.send_error(404, "Not Found")
            return
        try:
            route(self)
        except (BrokenPipeError, ConnectionResetError):
            pass

    def log_message(self, *args):
        pass


def answer(h, body=b"", status=200, length=True, **headers):
    """Status, headers (``length``: True = the real length, an int = that, None = none), body."""
    h.send_response(status)
    for name, value in headers.items():
        h.send_header(name.replace("_", "-"), value)
    if length is not None:
        h.send_header("Content-Length", str(len(body) if length is True else length))
    h.end_headers()
    h.wfile.write(body)


DRIP = 20  # bytes a dripping server offers at most


def drip(h, body, headers_too=False, every=1.0):
    """One byte per ``every`` seconds, at most DRIP bytes; ``server.dripped`` counts the bytes
    written before the client went away (fewer than DRIP: the deadline, not the server, ended it)."""
    if headers_too:
        data = b"HTTP/1.0 200 OK\r\nContent-Length: %d\r\n\r\n" % len(body) + body
    else:
        answer(h, b"", length=len(body), Content_Type="text/csv")
        data = body
    h.server.dripped = 0
    for byte in data[:DRIP]:
        h.wfile.write(bytes([byte]))
        h.wfile.flush()
        h.server.dripped += 1
        time.sleep(every)


def redirect(h, to, status=302):
    answer(h, b"", status=status, Location=to)


# case id -> (dataset, {path: behaviour}, extra CLI args, expected message regex)
CASES = {
    "http-truncated-content-length": (
        UNREG, {PATHS[UNREG]: lambda h: answer(h, csv_body()[:300], length=len(csv_body()))}, [],
        r"connection closed after 300 of 1\d\d\d bytes"),
    "http-truncated-registered-size": (
        REG, {PATHS[REG]: lambda h: answer(h, b"lat_gps,lon" * 100, length=REG_SIZE)}, [],
        rf"connection closed after 1100 of {REG_SIZE} bytes"),
    "http-chunked-truncated": (
        UNREG, {PATHS[UNREG]: lambda h: answer(h, b"64\r\n" + csv_body()[:40], length=None,
                                               Transfer_Encoding="chunked")}, [],
        r"cannot download bohai/20220822_0_7: connection closed before the end of the body \(url"),
    "http-close-delimited-registered-short": (
        REG, {PATHS[REG]: lambda h: answer(h, b"x" * 1000, length=None)}, [],
        rf"got 1000 bytes, the registered size is {REG_SIZE}"),
    "http-close-delimited-cut-mid-line": (
        UNREG, {PATHS[UNREG]: lambda h: answer(h, csv_body()[:-60], length=None)}, [],
        r"content check failed: line 6 has \d+ fields, the header 36: the body was cut short"),
    "http-close-delimited-cut-in-last-field": (
        UNREG, {PATHS[UNREG]: lambda h: answer(h, csv_body()[:-3], length=None)}, [],
        r"content check failed: the last line \(6\) has no line end: the body was cut short"),
    "http-html-page-200": (
        UNREG, {PATHS[UNREG]: lambda h: answer(h, HTML, Content_Type="text/html; charset=utf-8")}, [],
        r"the server sent an HTML page \(Content-Type text/html\), not the data file"),
    "http-html-page-as-text-plain": (
        UNREG, {PATHS[UNREG]: lambda h: answer(h, HTML, Content_Type="text/plain")}, [],
        r"content check failed: the first line is not a Bohai CSV header \(starts with '<!DOCTYPE html>'\)"),
    "http-wrong-header-layout": (
        UNREG, {PATHS[UNREG]: lambda h: answer(h, b"time,x,y\r\n0.0,1,2\r\n")}, [],
        r"content check failed: the first line is not a Bohai CSV header \(starts with 'time,x,y'\)"),
    "http-wrong-checksum": (
        REG, {PATHS[REG]: lambda h: answer(h, b"x" * REG_SIZE)}, [],
        rf"^replay: error: checksum mismatch for bohai/20220822_0_0: expected db16c328\w+, "
        rf"got {hashlib.sha256(b'x' * REG_SIZE).hexdigest()}; the download was discarded"),
    "http-wrong-size-announced": (
        REG, {PATHS[REG]: lambda h: answer(h, csv_body())}, [],
        rf"the server announces \d+ bytes, the registered size is {REG_SIZE}"),
    "http-oversize-close-delimited": (
        REG, {PATHS[REG]: lambda h: answer(h, b"y" * (REG_SIZE + 70000), length=None)}, [],
        rf"the server sent more than the registered size of {REG_SIZE} bytes"),
    "http-404": (UNREG, {}, [], r"cannot download bohai/20220822_0_7: HTTP 404 Not Found \(url http://127"),
    "http-500": (
        UNREG, {PATHS[UNREG]: lambda h: answer(h, b"oops", status=500)}, [],
        r"cannot download bohai/20220822_0_7: HTTP 500 Internal Server Error"),
    "http-slow-drip-body": (
        UNREG, {PATHS[UNREG]: lambda h: drip(h, csv_body())}, ["--deadline", "1.5"],
        r"cannot download bohai/20220822_0_7: not complete within the deadline of 1.5 s "
        r"\(\d bytes received\) \(url http://127\.0\.0\.1:\d+/20220822/0/20220822_0_7\.csv\)$"),
    "http-slow-drip-headers": (
        UNREG, {PATHS[UNREG]: lambda h: drip(h, csv_body(), headers_too=True, every=0.2)}, ["--deadline", "1"],
        r"not complete within the deadline of 1 s \(0 bytes received\)"),
    "http-redirect-loop": (
        UNREG, {PATHS[UNREG]: lambda h: redirect(h, "/a"), "/a": lambda h: redirect(h, "/b"),
                "/b": lambda h: redirect(h, PATHS[UNREG], 301)}, [],
        r"redirect loop: back to http://127\.0\.0\.1:\d+/20220822/0/20220822_0_7\.csv at redirect 3"),
    "http-redirect-chain-too-long": (
        UNREG, {PATHS[UNREG]: lambda h: redirect(h, "/r1"),
                **{f"/r{i}": (lambda i: lambda h: redirect(h, f"/r{i + 1}"))(i) for i in range(1, 10)}}, [],
        r"more than 5 redirects"),
    "http-redirect-to-ftp": (
        UNREG, {PATHS[UNREG]: lambda h: redirect(h, "ftp://127.0.0.1/x.csv")}, [],
        r"redirected to ftp://127\.0\.0\.1/x\.csv, which is not an http\(s\) URL"),
    "http-empty-body-content-length-0": (
        UNREG, {PATHS[UNREG]: lambda h: answer(h, b"")}, [], r"the server sent an empty body \(Content-Length 0\)"),
    "http-empty-body-close-delimited": (
        UNREG, {PATHS[UNREG]: lambda h: answer(h, b"", length=None)}, [], r"the server sent an empty body \(url"),
    "http-gzip-encoded-garbage": (
        UNREG, {PATHS[UNREG]: lambda h: answer(h, b"\x1f\x8b\x08\x00garbage", Content_Encoding="gzip")}, [],
        r"the server sent gzip-encoded content, which was not asked for"),
    "http-gzip-bytes-as-plain": (
        UNREG, {PATHS[UNREG]: lambda h: answer(h, gzip.compress(csv_body()), Content_Type="text/csv")}, [],
        r"content check failed: a gzip stream, not a CSV \(starts with bytes 1f 8b 08 "),
    "http-closed-without-answer": (
        UNREG, {PATHS[UNREG]: lambda h: None}, [], r"the server closed the connection without an answer"),
    "http-garbage-status-line": (
        UNREG, {PATHS[UNREG]: lambda h: h.wfile.write(b"HELLO THERE\r\n\r\n")}, [],
        r"not a valid HTTP answer \(BadStatusLine"),
}
register(*CASES)


@pytest.fixture
def server(tmp_path):
    """A scripted loopback server; its ``routes`` are set by each test."""
    srv = http.server.ThreadingHTTPServer(("127.0.0.1", 0), Scripted)
    srv.routes = {}
    thread = threading.Thread(target=srv.serve_forever, args=(0.05,), daemon=True)
    thread.start()
    yield srv, f"http://127.0.0.1:{srv.server_address[1]}"
    srv.shutdown()
    srv.server_close()


@pytest.mark.slow  # waits out deadlines (over 1 s): the full suite runs it
@pytest.mark.parametrize("case", list(CASES))
def test_hostile_answer_is_refused(case, server, tmp_path):
    srv, base = server
    ds, routes, extra, match = CASES[case]
    srv.routes = routes
    dest = tmp_path / "dest"
    env = {"REPLAY_DATASET_BASE_URL": base, "REPLAY_CACHE_DIR": str(tmp_path / "cache")}
    line = assert_refused(["datasets", "fetch", ds, "--dest", dest, *extra], match, env=env)
    assert line.startswith("replay: error: ") and ("(url http://127.0.0.1:" in line)
    # nothing under the final name, no temporary file, no checksum recorded
    assert not dest.exists() or sorted(p.name for p in dest.iterdir()) == []
    if "drip" in case:  # the client left before the server had offered everything
        assert srv.dripped < DRIP


@pytest.mark.slow  # waits out deadlines (over 1 s): the full suite runs it
def test_tls_handshake_drip_ends_at_the_deadline(tmp_path):
    """An https server that answers the TLS ClientHello with a record header announcing 16 KB and
    then one byte every 0.2 s (each byte resets the 30 s silence timeout): the 1 s deadline ends it,
    long before the server has offered its DRIP bytes."""
    sent = []

    def serve(sock):
        conn, _ = sock.accept()
        with conn:
            conn.recv(4096)  # the ClientHello
            conn.sendall(b"\x16\x03\x03\x40\x00")  # handshake record, 16384 bytes follow
            try:
                for _ in range(DRIP):
                    conn.sendall(b"\x00")
                    sent.append(1)
                    time.sleep(0.2)
            except OSError:
                pass

    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        sock.listen(4)
        thread = threading.Thread(target=serve, args=(sock,), daemon=True)
        thread.start()
        base = f"https://127.0.0.1:{sock.getsockname()[1]}"
        line = assert_refused(["datasets", "fetch", UNREG, "--dest", tmp_path / "d", "--deadline", "1"],
                              r"not complete within the deadline of 1 s \(0 bytes received\) \(url https://",
                              env={"REPLAY_DATASET_BASE_URL": base})
        thread.join(10)
    assert line.endswith("/20220822/0/20220822_0_7.csv)") and not (tmp_path / "d" / "20220822_0_7.csv").exists()
    assert 0 < len(sent) < DRIP


register("https-handshake-drip")


def test_damaged_record_file_is_refused_in_one_line(server, tmp_path):
    """A checksums.json that is not JSON beside a present file: one line naming it; --force rewrites it."""
    srv, base = server
    srv.routes = {PATHS[UNREG]: lambda h: answer(h, csv_body(2))}
    dest = tmp_path / "d"
    dest.mkdir()
    (dest / "20220822_0_7.csv").write_bytes(csv_body(2))
    (dest / "checksums.json").write_text("{not json")
    env = {"REPLAY_DATASET_BASE_URL": base}
    assert_refused(["datasets", "fetch", UNREG, "--dest", dest],
                   r"^replay: error: .*checksums\.json: cannot read recorded checksums: ", env=env)
    from hostile import assert_ok

    assert_ok(["datasets", "fetch", UNREG, "--dest", dest, "--force"], env=env)
    assert '"content_checked": true' in (dest / "checksums.json").read_text()


register("fetch-record-damaged")


BAD_DEADLINES = {"fetch-deadline-zero": "0", "fetch-deadline-negative": "-3", "fetch-deadline-nan": "nan",
                 "fetch-deadline-inf": "inf"}
register(*BAD_DEADLINES)


@pytest.mark.parametrize("case", list(BAD_DEADLINES))
def test_bad_deadline_is_refused_before_any_request(case, server, tmp_path):
    srv, base = server
    asked = []
    srv.routes = {PATHS[UNREG]: lambda h: asked.append(1) or answer(h, csv_body())}
    value = BAD_DEADLINES[case]
    assert_refused(["datasets", "fetch", UNREG, "--dest", tmp_path / "d", "--deadline", value],
                   rf"^replay: error: download deadline must be a positive number of seconds \(got {value}",
                   env={"REPLAY_DATASET_BASE_URL": base})
    assert asked == [] and not (tmp_path / "d").exists()


def test_refusal_keeps_the_copy_that_was_there(server, tmp_path):
    """--force with a hostile answer: the existing file is left as it was."""
    srv, base = server
    dest = tmp_path / "dest"
    env = {"REPLAY_DATASET_BASE_URL": base, "REPLAY_CACHE_DIR": str(tmp_path / "cache")}
    srv.routes = {PATHS[UNREG]: lambda h: answer(h, csv_body(3))}
    from hostile import assert_ok

    assert_ok(["datasets", "fetch", UNREG, "--dest", dest], env=env)
    before = {p.name: p.read_bytes() for p in dest.iterdir()}
    srv.routes = {PATHS[UNREG]: lambda h: answer(h, HTML, Content_Type="text/plain")}
    assert_refused(["datasets", "fetch", UNREG, "--dest", dest, "--force"], r"content check failed", env=env)
    assert {p.name: p.read_bytes() for p in dest.iterdir()} == before


def test_a_correct_answer_through_a_redirect_is_accepted(server, tmp_path):
    srv, base = server
    srv.routes = {PATHS[UNREG]: lambda h: redirect(h, "/mirror/file.csv", 307),
                  "/mirror/file.csv": lambda h: answer(h, csv_body(4), Content_Type="text/plain")}
    from hostile import assert_ok

    env = {"REPLAY_DATASET_BASE_URL": base, "REPLAY_CACHE_DIR": str(tmp_path / "cache")}
    out = assert_ok(["datasets", "fetch", UNREG, "--dest", tmp_path / "d"], env=env).stdout
    assert "as announced by the server" in out and "content-checked: 36-column Bohai CSV, 4 rows" in out
    assert (tmp_path / "d" / "20220822_0_7.csv").read_bytes() == csv_body(4)
