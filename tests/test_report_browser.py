"""`report.html` in headless Chromium: it renders (the screenshot is not blank and shows the
figures in the filters' colours) and loads no external resource.

Chromium is Debian's ``chromium`` (``.ci/run`` installs it when missing). Without it the test
skips with that reason, except under CI (``CI`` or ``REPLAY_REQUIRE_SHARED`` set), where it fails.
Two independent checks that nothing external is loaded: the page's markup names no URL but
``data:`` ones (and carries a Content-Security-Policy), and Chromium's network log, with every
host name unresolvable, shows no request from the page but for the file itself. A control page
with one external image proves that the log check sees such a request.
"""
import json
import os
import shutil
import subprocess
from html.parser import HTMLParser
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from replay.cli import main
from replay.outputs.palette import FIXED

CHROMIUM = next((shutil.which(n) for n in ("chromium", "chromium-browser") if shutil.which(n)), None)
IN_CI = bool(os.environ.get("CI") or os.environ.get("REPLAY_REQUIRE_SHARED"))
WIDTH, HEIGHT = 1400, 5000

CAMPAIGN = """\
[campaign]
runs = 6
batch = 6

[[dataset]]
id = "sim/auv-sonar"
params = { steps = 40 }

[[filter]]
name = "ekf"

[[filter]]
name = "pf"
params = { n_particles = 200 }
"""


def _need_chromium():
    if CHROMIUM is None:
        if IN_CI:
            pytest.fail("chromium not found: .ci/run installs Debian's chromium for this test")
        pytest.skip("chromium not found (Debian: apt-get install chromium); required under CI")


def render(html_path: Path, work: Path):
    """(screenshot RGB array, [(url, network isolation key)] requested) of a page in headless Chromium."""
    shot, net = work / "shot.png", work / "net.json"
    cmd = [CHROMIUM, "--headless", "--no-sandbox", "--disable-gpu", "--hide-scrollbars", "--no-first-run",
           "--disable-background-networking", "--disable-component-update", "--disable-sync",
           "--disable-extensions", f"--user-data-dir={work / 'profile'}",
           "--host-resolver-rules=MAP * ~NOTFOUND", f"--log-net-log={net}", "--virtual-time-budget=5000",
           f"--window-size={WIDTH},{HEIGHT}", f"--screenshot={shot}", html_path.resolve().as_uri()]
    res = subprocess.run(cmd, capture_output=True, text=True, timeout=180)
    assert shot.is_file(), f"chromium wrote no screenshot (exit {res.returncode}): {res.stderr[-2000:]}"
    from PIL import Image

    img = np.asarray(Image.open(shot).convert("RGB"))
    text = net.read_text().rstrip()
    try:
        log = json.loads(text)
    except json.JSONDecodeError:  # a log cut short (Chromium ended before closing it): close it
        log = json.loads(text.rstrip(",") + "]}")
    start = log["constants"]["logEventTypes"]["URL_REQUEST_START_JOB"]
    reqs = [(e["params"]["url"], e["params"].get("network_isolation_key", ""))
            for e in log["events"] if e["type"] == start and "url" in e.get("params", {})]
    return img, reqs


def page_requests(reqs):
    """The requests the page made (its network isolation key is the file: site), but the page itself."""
    return [u for u, key in reqs if "file://" in key and not u.startswith(("file:", "data:"))]


class _Refs(HTMLParser):
    def __init__(self):
        super().__init__()
        self.urls, self.tags = [], set()

    def handle_starttag(self, tag, attrs):
        self.tags.add(tag)
        for k, v in attrs:
            if k in ("src", "href", "srcset", "poster", "data", "action", "background") and v:
                self.urls.append(v)


@pytest.mark.slow
def test_report_renders_in_chromium_and_loads_nothing_external(tmp_path):
    _need_chromium()
    (tmp_path / "c.toml").write_text(CAMPAIGN)
    out = tmp_path / "camp"
    res = CliRunner().invoke(main, ["campaign", "run", str(tmp_path / "c.toml"), "-o", str(out), "-w", "1", "-q"])
    assert res.exit_code == 0, res.output
    res = CliRunner().invoke(main, ["report", str(out)])
    assert res.exit_code == 0, res.output
    page = out / "report" / "report.html"
    text = page.read_text()

    refs = _Refs()
    refs.feed(text)
    assert refs.urls and all(u.startswith("data:image/png;base64,") for u in refs.urls)
    assert not refs.tags & {"script", "link", "iframe", "object", "embed", "video", "audio", "source"}
    assert "url(" not in text and "@import" not in text and "Content-Security-Policy" in text

    img, reqs = render(page, tmp_path)
    assert img.shape[:2] == (HEIGHT, WIDTH)
    assert page_requests(reqs) == []
    white = (img > 245).all(axis=2)
    assert 0.05 < 1 - white.mean() and img.std() > 20  # not blank
    for name in ("ekf", "pf"):  # the figures rendered, in each filter's palette colour
        rgb = np.array([int(FIXED[name][k:k + 2], 16) for k in (1, 3, 5)])
        assert (np.abs(img.astype(int) - rgb).max(axis=2) <= 8).sum() > 2000, name


@pytest.mark.slow
def test_the_network_check_sees_an_external_load(tmp_path):
    _need_chromium()
    page = tmp_path / "control.html"
    page.write_text("<!doctype html><html><body><p>control</p><img src='https://example.invalid/x.png'></body></html>")
    _, reqs = render(page, tmp_path)
    assert page_requests(reqs) == ["https://example.invalid/x.png"]
