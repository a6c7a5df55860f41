"""Downloading datasets from a loopback HTTP server laid out like the upstream repository.

The server serves a tmp directory holding symlinks (or corrupted copies) at the
upstream paths (e.g. ``20220822/0/20220822_0_0.csv``), and
``$REPLAY_DATASET_BASE_URL`` points at it, so URLs are built exactly as for the
real upstream: ``<base>/<upstream_path>``.
"""
import functools
import http.server
import json
import os
import socket
import threading
from pathlib import Path

import click

from replay.cli import main as replay_main
import pytest
from click.testing import CliRunner

from replay import registry
from replay.util.errors import ReplayError
from replay.fetch import download_url, fetch

REPO = Path(__file__).resolve().parents[1]
SHARED = Path(os.environ.get("REPLAY_SHARED", REPO.parent / "shared"))
BOHAI = SHARED / "datasets" / "bohai"
needs_shared = pytest.mark.skipif(not (BOHAI / "20220822_0_0.csv").is_file(),
                                  reason=f"shared Bohai files not found at {BOHAI} (set REPLAY_SHARED)")


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


@needs_shared
def test_fetch_verifies_and_second_fetch_is_a_noop(upstream, tmp_path):
    root, _ = upstream
    served = publish(root, "bohai/20220822_0_0", source=BOHAI / "20220822_0_0.csv")
    dest = tmp_path / "dest"
    result = fetch("bohai/20220822_0_0", dest)
    assert result.path == dest / "20220822_0_0.csv"
    assert result.verified and result.downloaded
    assert result.sha256 == registry.get("bohai/20220822_0_0").sha256
    assert result.path.stat().st_size == 1071327
    assert "sha256 verified" in result.message
    assert leftovers(dest) == [] and not (dest / "checksums.json").exists()

    served.unlink()  # a second fetch must not even ask the server
    again = fetch("bohai/20220822_0_0", dest)
    assert not again.downloaded and again.verified and again.path == result.path
    assert "already present" in again.message
    assert registry.locate("bohai/20220822_0_0", dest) == result.path


@needs_shared
def test_fetch_defaults_to_the_cache(upstream, tmp_path):
    root, _ = upstream
    publish(root, "bohai/20220822_0_0", source=BOHAI / "20220822_0_0.csv")
    result = fetch("bohai/20220822_0_0")
    assert result.path == tmp_path / "cache" / "bohai" / "20220822_0_0.csv"
    assert registry.locate("bohai/20220822_0_0") == result.path


@needs_shared
def test_corrupted_download_is_refused(upstream, tmp_path):
    root, _ = upstream
    data = bytearray((BOHAI / "20220822_0_0.csv").read_bytes())
    data[5000] ^= 1
    publish(root, "bohai/20220822_0_0", data=bytes(data))
    dest = tmp_path / "dest"
    with pytest.raises(ReplayError) as err:
        fetch("bohai/20220822_0_0", dest)
    msg = str(err.value)
    assert msg.startswith("checksum mismatch for bohai/20220822_0_0: expected db16c328")
    assert "the download was discarded" in msg and "\n" not in msg
    assert list(dest.iterdir()) == []  # neither the final name nor a temp file


@needs_shared
def test_mismatching_local_copy_is_replaced(upstream, tmp_path):
    root, _ = upstream
    publish(root, "bohai/20220822_0_0", source=BOHAI / "20220822_0_0.csv")
    dest = tmp_path / "dest"
    dest.mkdir()
    (dest / "20220822_0_0.csv").write_text("edited\n")
    result = fetch("bohai/20220822_0_0", dest)
    assert result.downloaded and result.verified and "replaced" in result.message


def test_unknown_checksum_is_accepted_and_recorded(upstream, tmp_path):
    root, base = upstream
    publish(root, "bohai/20220822_0_7", data=b"time,x\n0.0,1\n0.1,2\n")
    dest = tmp_path / "dest"
    result = fetch("bohai/20220822_0_7", dest)
    assert result.downloaded and not result.verified
    assert result.path.read_bytes() == b"time,x\n0.0,1\n0.1,2\n"
    assert result.sha256 == registry.sha256_file(result.path)
    assert "checksum not known upstream; recorded sha256 " + result.sha256 in result.message
    recorded = json.loads((dest / "checksums.json").read_text())
    assert recorded["20220822_0_7.csv"]["sha256"] == result.sha256
    assert recorded["20220822_0_7.csv"]["dataset"] == "bohai/20220822_0_7"
    assert recorded["20220822_0_7.csv"]["url"] == base + "/20220822/0/20220822_0_7.csv"
    assert leftovers(dest) == []
    again = fetch("bohai/20220822_0_7", dest)
    assert not again.downloaded and "matches the checksum recorded" in again.message
    assert registry.check_file(registry.get("bohai/20220822_0_7"), result.path) == (result.sha256, "recorded")


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


def test_sims_are_not_downloaded(tmp_path):
    with pytest.raises(ReplayError, match="generated on demand"):
        fetch("sim/auv-sonar", tmp_path)




def test_cli_fetch(upstream, tmp_path):
    root, _ = upstream
    publish(root, "bohai/20220822_0_7", data=b"time\n0\n")
    publish(root, "bohai/20220822_0_8", data=b"time\n1\n")
    dest = tmp_path / "dest"
    runner = CliRunner()
    result = runner.invoke(replay_main, ["datasets", "fetch", "bohai/20220822_0_7", "bohai/20220822_0_8", "--dest", str(dest)])
    assert result.exit_code == 0, result.output
    assert result.output.count("recorded sha256") == 2
    assert sorted(p.name for p in dest.iterdir()) == ["20220822_0_7.csv", "20220822_0_8.csv", "checksums.json"]
    result = runner.invoke(replay_main, ["datasets", "fetch", "bohai/20220822_0_1", "--dest", str(dest)])
    assert result.exit_code == 2
    assert result.output.startswith("replay: error: cannot download bohai/20220822_0_1: HTTP 404")
    result = runner.invoke(replay_main, ["datasets", "fetch"])
    assert result.exit_code == 2 and "--all" in result.output
