"""Hostile downloads of sequences without a registered checksum, and what downloads leave behind
(issue 23): a body that is another sequence, a body cut at a line end without a Content-Length,
stale ``.part`` files of killed downloads, server bytes in an error line, a bad base URL.

The loopback server and its scripted answers are those of ``tests/test_hostile_http.py``.
"""
import json
import os
import re
import shutil
import subprocess
import sys
import time

import pytest
from hostile import assert_ok, assert_refused, register
from test_hostile_http import PATHS, UNREG, answer, csv_body, server  # noqa: F401 (server: the fixture)

from replay.data import registry
from replay.data.checksums import bohai_csv, declared_mismatch
from replay.util import downloads

OTHER = "bohai/20220822_0_8"  # a second sequence without a registered checksum
PATHS = dict(PATHS, **{OTHER: "/20220822/0/20220822_0_8.csv"})


def env_for(base, tmp_path):
    return {"REPLAY_DATASET_BASE_URL": base, "REPLAY_CACHE_DIR": str(tmp_path / "cache"), "REPLAY_DATA_DIR": ""}


def cut(body: bytes, share: float) -> bytes:
    """``body`` cut at a line end after ``share`` of its lines (the header kept)."""
    lines = body.splitlines(keepends=True)
    return b"".join(lines[:max(2, round(len(lines) * share))])


@pytest.fixture
def declaring(tmp_path, monkeypatch):
    """The manifests, with bohai/20220822_0_7 declaring rows = 10 and span_s = 9 (csv_body(10): time
    0.34 ... 9.34 s), as an upstream listing would."""
    src, man = registry.manifests_dir(), tmp_path / "manifests"
    shutil.copytree(src, man)
    text = (man / "bohai.toml").read_text()
    text = text.replace('id = "bohai/20220822_0_7"\n', 'id = "bohai/20220822_0_7"\nrows = 10\nspan_s = 9\n')
    (man / "bohai.toml").write_text(text)
    monkeypatch.setattr(registry, "manifests_dir", lambda: man)
    assert registry.get(UNREG).rows == 10
    return man


# ---------------------------------------------------------------- another sequence's body

def test_registered_sequence_served_as_another_is_refused(server, tmp_path, bohai_dir):
    """0_0's bytes (registered checksum) served as 0_7 (paper 002's sequence): one line naming both."""
    srv, base = server
    body = (bohai_dir / "20220822_0_0.csv").read_bytes()
    srv.routes = {PATHS[UNREG]: lambda h: answer(h, body, Content_Type="text/csv")}
    dest = tmp_path / "d"
    assert_refused(["datasets", "fetch", UNREG, "--dest", dest],
                   r"^replay: error: cannot download bohai/20220822_0_7: the body is byte-identical to "
                   r"bohai/20220822_0_0 \(its registered sha256\), not bohai/20220822_0_7; the download was "
                   r"discarded \(url http://127\.0\.0\.1:\d+/20220822/0/20220822_0_7\.csv\)$", env=env_for(base, tmp_path))
    assert not dest.exists() or sorted(p.name for p in dest.iterdir()) == []
    # the same bytes put there by hand: loading refuses them too (info, eval), one line
    dest.mkdir(exist_ok=True)
    shutil.copy(bohai_dir / "20220822_0_0.csv", dest / "20220822_0_7.csv")
    for cmd in (["datasets", "info", UNREG], ["eval", UNREG, "--filters", "ekf", "--first", "50"]):
        assert_refused([*cmd, "--data-dir", dest], r"20220822_0_7\.csv: this file is byte-identical to "
                       r"bohai/20220822_0_0 \(its registered sha256\), so it is not bohai/20220822_0_7",
                       env=env_for(base, tmp_path), cwd=tmp_path)
    # fetch replaces it with the right file
    srv.routes = {PATHS[UNREG]: lambda h: answer(h, csv_body(4))}
    out = assert_ok(["datasets", "fetch", UNREG, "--dest", dest], env=env_for(base, tmp_path)).stdout
    assert "the local copy was not bohai/20220822_0_7 (bohai/20220822_0_0 (its registered sha256)) and was replaced" in out
    assert (dest / "20220822_0_7.csv").read_bytes() == csv_body(4)


def test_sequence_downloaded_earlier_served_as_another_is_refused(server, tmp_path):
    """0_7's body, downloaded and recorded, served again as 0_8 into the same directory."""
    srv, base = server
    srv.routes = {PATHS[UNREG]: lambda h: answer(h, csv_body(5)), PATHS[OTHER]: lambda h: answer(h, csv_body(5))}
    dest, env = tmp_path / "d", env_for(base, tmp_path)
    assert_ok(["datasets", "fetch", UNREG, "--dest", dest], env=env)
    assert_refused(["datasets", "fetch", OTHER, "--dest", dest],
                   r"cannot download bohai/20220822_0_8: the body is byte-identical to bohai/20220822_0_7 "
                   r"\(its sha256 recorded at download in checksums\.json\), not bohai/20220822_0_8", env=env)
    assert sorted(p.name for p in dest.iterdir()) == ["20220822_0_7.csv", "checksums.json"]


register("fetch-body-of-registered-sequence", "fetch-body-of-recorded-sequence")


# ---------------------------------------------------------------- a body cut at a line end

def test_cut_at_a_line_end_is_refused_where_rows_and_span_are_declared(server, tmp_path, declaring):
    """60 % of the lines, cut at a line end, no Content-Length: the declared rows and span refuse it."""
    srv, base = server
    srv.routes = {PATHS[UNREG]: lambda h: answer(h, cut(csv_body(10), 0.6), length=None)}
    dest, env = tmp_path / "d", env_for(base, tmp_path)
    assert_refused(["datasets", "fetch", UNREG, "--dest", dest],
                   r"cannot download bohai/20220822_0_7: the body holds 6 rows, the upstream listing declares "
                   r"10; a time span of 5\.0 s, the upstream listing declares 9 s: cut short or another file; "
                   r"the download was discarded \(url", env=env)
    assert not dest.exists() or list(dest.iterdir()) == []
    # a time column in milliseconds: the rows match, the span does not
    body = csv_body(10).replace(b"\r\n", b"\n")
    lines = body.splitlines()
    ms = [lines[0]] + [b",".join(c if i != 34 else b"%.0f" % (float(c) * 1000) for i, c in enumerate(ln.split(b",")))
                       for ln in lines[1:]]
    srv.routes = {PATHS[UNREG]: lambda h: answer(h, b"\n".join(ms) + b"\n", length=None)}
    assert_refused(["datasets", "fetch", UNREG, "--dest", dest],
                   r"the body holds a time span of 9000\.0 s, the upstream listing declares 9 s", env=env)
    # the whole body: accepted, recorded as matching the declaration, rows content_checked
    srv.routes = {PATHS[UNREG]: lambda h: answer(h, csv_body(10), length=None)}
    out = assert_ok(["datasets", "fetch", UNREG, "--dest", dest], env=env).stdout
    assert "rows and time span as the upstream listing declares" in out
    assert json.loads((dest / "checksums.json").read_text())["20220822_0_7.csv"]["declared_checked"] is True


def test_cut_at_a_line_end_is_refused_where_the_size_is_declared(server, tmp_path, monkeypatch):
    """A manifest declaring only ``size`` (no checksum, no rows): a body cut at a line end, no Content-Length,
    is refused against it and never stored (issue 33, item 6); the whole body is stored."""
    src, man = registry.manifests_dir(), tmp_path / "manifests"
    shutil.copytree(src, man)
    whole = csv_body(10)
    text = (man / "bohai.toml").read_text()
    (man / "bohai.toml").write_text(
        text.replace('id = "bohai/20220822_0_7"\n', f'id = "bohai/20220822_0_7"\nsize = {len(whole)}\n'))
    monkeypatch.setattr(registry, "manifests_dir", lambda: man)
    assert registry.get(UNREG).size == len(whole) and registry.get(UNREG).rows is None
    srv, base = server
    short = cut(whole, 0.6)
    srv.routes = {PATHS[UNREG]: lambda h: answer(h, short, length=None)}
    dest, env = tmp_path / "d", env_for(base, tmp_path)
    assert_refused(["datasets", "fetch", UNREG, "--dest", dest],
                   rf"cannot download bohai/20220822_0_7: got {len(short)} bytes, the registered size is "
                   rf"{len(whole)} \(url", env=env)
    assert not dest.exists() or list(dest.iterdir()) == []
    srv.routes = {PATHS[UNREG]: lambda h: answer(h, whole, length=None)}
    assert_ok(["datasets", "fetch", UNREG, "--dest", dest], env=env)
    assert (dest / "20220822_0_7.csv").read_bytes() == whole


def test_cut_at_a_line_end_without_declaration_is_never_stored(server, tmp_path, bohai_dir):
    """Nothing declared and no Content-Length: the cut body (60 % of 0_6, at a line end) could not be told
    from a whole file, so it is refused and nothing is stored (issue 33, item 6). With the length announced
    (and received whole), nothing declared: stored, said unconfirmed, and every leaderboard row on it
    carries content_checked False (a whole registered file: True)."""
    import replay

    srv, base = server
    body = cut((bohai_dir / "20220822_0_6.csv").read_bytes(), 0.6)
    srv.routes = {PATHS[UNREG]: lambda h: answer(h, body, length=None)}
    dest, env = tmp_path / "d", env_for(base, tmp_path)
    assert_refused(["datasets", "fetch", UNREG, "--dest", dest],
                   r"cannot download bohai/20220822_0_7: the server announced no size and .*bohai\.toml declares "
                   r"no size, rows or span_s for bohai/20220822_0_7: a body cut at a line end could not be told "
                   r"from the whole file; the download was discarded", env=env)
    assert not (dest / "20220822_0_7.csv").exists() and not (dest / "checksums.json").exists()
    assert not dest.exists() or not [p for p in dest.iterdir() if p.name.endswith(".part")]
    srv.routes = {PATHS[UNREG]: lambda h: answer(h, body)}  # Content-Length announced and received
    out = assert_ok(["datasets", "fetch", UNREG, "--dest", dest], env=env).stdout
    assert "as announced by the server" in out and "4505 rows" in out
    assert "nothing published to check it against: rows using it say content_checked=false" in out
    assert json.loads((dest / "checksums.json").read_text())["20220822_0_7.csv"]["declared_checked"] is False
    ev = replay.evaluate(UNREG, filters=["ekf"], first=100, data_dir=dest)
    assert ev.frame_meta["content_checked"] is False and {r["filter"]: r["content_checked"] for r in ev.rows} == {
        "ekf": False, "measurements": False}
    ev = replay.evaluate("bohai/20220822_0_6", filters=["ekf"], first=100, data_dir=bohai_dir)
    assert [r["content_checked"] for r in ev.rows] == [True, True]  # ekf, measurements
    assert "content_checked" not in replay.evaluate("sim/ungm", filters=["ekf"], runs=1).rows[0]


def test_declared_rows_and_spans_match_the_real_files(bohai_dir):
    """Every manifest entry declaring rows or span whose file is here: the content check agrees (spans are
    declared to the second); one row or one second more is a mismatch."""
    import dataclasses

    seen = 0
    for ds in registry.all_datasets().values():
        path = bohai_dir / (ds.file or "-")
        if ds.rows is None or not path.is_file():
            continue
        content = bohai_csv(path)
        assert declared_mismatch(ds, content) is None, ds.id
        assert declared_mismatch(dataclasses.replace(ds, rows=ds.rows + 1), content)
        assert declared_mismatch(dataclasses.replace(ds, span_s=ds.span_s + 1), content)
        seen += 1
    assert seen == 6


@pytest.mark.parametrize(("head", "said"), [
    (b"\x1f\x8b\x08\x00'\x22\x0ck" + b"x" * 40, "a gzip stream, not a CSV (starts with bytes 1f 8b 08 00 27 22 0c 6b)"),
    (b"PK\x03\x04" + b"\x00" * 40, "a zip archive, not a CSV (starts with bytes 50 4b 03 04 00 00 00 00)"),
    (b"time,lat\n1,\x002\n", "binary data, not a CSV (starts with bytes 74 69 6d 65 2c 6c 61 74)")])
def test_binary_content_is_named_in_hex_whatever_its_bytes(tmp_path, head, said):
    """A binary body is refused with its first bytes in hex: the same line for any bytes (a gzip header's
    time stamp holding a quote once turned repr's quotes around and the message with them)."""
    path = tmp_path / "x.csv"
    path.write_bytes(head)
    with pytest.raises(ValueError) as e:
        bohai_csv(path)
    assert str(e.value) == said


register("fetch-cut-at-line-end-declared", "fetch-time-in-ms-declared", "fetch-cut-at-line-end-undeclared")


# ---------------------------------------------------------------- .part files of killed downloads

def test_stale_part_files_are_removed_and_counted(server, tmp_path):
    """Temporary files of downloads whose process is gone are removed by the next download into the
    directory, and counted; one of a running download, of another machine, a recent owner-less one
    and anything not ours stay."""
    srv, base = server
    srv.routes = {PATHS[UNREG]: lambda h: answer(h, csv_body(3))}
    dest = tmp_path / "d"
    dest.mkdir()
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    live = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    host = downloads._host()
    try:
        stale = {f".20220822_0_7.csv.{dead.pid}@{host}.abcd1234.part": 1000,
                 f".20220822_0_3.csv.{dead.pid}@{host}.zz_z9999.part": 500,
                 f".checksums.json.{dead.pid}@{host}.q1w2e3r4.part": 10,
                 ".20220822_0_7.csv.oldlegac.part": 7}
        kept = {f".20220822_0_7.csv.{live.pid}@{host}.abcd1235.part": 3,
                f".20220822_0_7.csv.{dead.pid}@another-host.abcd1236.part": 3,
                ".20220822_0_7.csv.newlegac.part": 3, "notes.part": 3}
        for name, size in {**stale, **kept}.items():
            (dest / name).write_bytes(b"x" * size)
        old = time.time() - 2 * downloads.LEGACY_AGE
        os.utime(dest / ".20220822_0_7.csv.oldlegac.part", (old, old))
        out = assert_ok(["datasets", "fetch", UNREG, "--dest", dest], env=env_for(base, tmp_path)).stdout
    finally:
        live.kill()
        live.wait()
    assert "; removed 4 partial files of interrupted downloads (1517 bytes)" in out
    assert sorted(p.name for p in dest.iterdir()) == sorted([*kept, "20220822_0_7.csv", "checksums.json"])


register("fetch-stale-part-files")


# ---------------------------------------------------------------- server bytes in an error line

RAW = {
    "fetch-status-reason-control-bytes": (
        lambda h: h.wfile.write(b"HTTP/1.0 503 \x1b[31mevil\x07\x7f " + b"A" * 3000 + b"\r\n\r\n"),
        r"HTTP 503 \\x1b\[31mevil\\x07\\x7f A+… \(url"),
    "fetch-encoding-header-escape": (
        lambda h: answer(h, b"x", Content_Encoding="\x1b]0;pwned\x07"),
        r"the server sent \\x1b\]0;pwned\\x07-encoded content"),
    "fetch-redirect-to-bad-ipv6": (
        lambda h: answer(h, b"", status=302, Location="http://[::1/x\x1b[2J"),
        r"cannot download bohai/20220822_0_7: redirected to http://\[::1/x\\x1b\[2J, which is not a valid URL "
        r"\(Invalid IPv6 URL\) \(url"),
    "fetch-latin1-reason": (
        lambda h: h.wfile.write(b"HTTP/1.0 500 Fehler \xe4\xf6\r\n\r\n"), r"HTTP 500 Fehler \\xe4\\xf6 \(url"),
}
register(*RAW)


@pytest.mark.parametrize("case", list(RAW))
def test_server_bytes_are_printable_and_bounded_in_the_error_line(case, server, tmp_path):
    srv, base = server
    route, match = RAW[case]
    srv.routes = {PATHS[UNREG]: route}
    line = assert_refused(["datasets", "fetch", UNREG, "--dest", tmp_path / "d"], match, env=env_for(base, tmp_path))
    assert re.fullmatch(r"[ -~…]+", line) and len(line) < 700


# ---------------------------------------------------------------- the base URL

BAD_BASES = {"fetch-base-url-ipv6-unclosed": ("http://[::1", r"is not a valid URL \(Invalid IPv6 URL\)"),
             "fetch-base-url-port-range": ("http://127.0.0.1:99999", r"is not a valid URL \(Port out of range"),
             "fetch-base-url-ftp": ("ftp://mirror.example.org/data", r"is not an http\(s\) URL with a host"),
             "fetch-base-url-no-scheme": ("mirror.example.org/data", r"is not an http\(s\) URL with a host"),
             "fetch-base-url-no-host": ("https://", r"is not an http\(s\) URL with a host"),
             "fetch-base-url-control": ("http://h\x1b[2J/", r"'http://h\\x1b\[2J/' is not")}
register(*BAD_BASES)


@pytest.mark.parametrize("case", list(BAD_BASES))
def test_bad_base_url_is_refused_in_one_line(case, tmp_path):
    value, match = BAD_BASES[case]
    line = assert_refused(["datasets", "fetch", UNREG, "--dest", tmp_path / "d"], match,
                          env={"REPLAY_DATASET_BASE_URL": value})
    assert line.startswith("replay: error: $REPLAY_DATASET_BASE_URL '") and re.fullmatch(r"[ -~…]+", line)
    assert not (tmp_path / "d").exists()
