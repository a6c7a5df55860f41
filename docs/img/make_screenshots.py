"""Make the pictures of docs/first_ten_minutes.md again: ``python docs/img/make_screenshots.py``.

In a temporary directory it runs, as the page does,

    replay eval sim/auv-sonar --runs 20 -o run -q
    replay report run
    replay export run --mcap run.mcap -q

then writes beside this script

* ``report.png``: the top of ``run/report/report.html`` as headless Chromium renders it
  (1280 px wide; the flags of tests/test_report_browser.py: no network, no profile);
* ``mcap_channels.png``: what ``run.mcap`` holds, read back with the ``mcap`` Python reader: a
  table of its channels (topic, schema, message count, what it shows) and a plot of the poses and
  position errors decoded from the file, as an HTML page rendered by the same Chromium. It is a
  picture generated from the exported file, not a Foxglove Studio screenshot.

Needs the project installed (``pip install -e .``), Debian's ``chromium`` and Pillow (with
matplotlib). The PNGs are quantised to 256 colours to stay small.
"""

from __future__ import annotations

import base64
import html
import io
import json
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]
WIDTH = 1280
WHAT = {  # channel name suffix -> what a Foxglove panel shows of it
    "pose": "the estimate's position and heading at each step (3D panel)",
    "path": "the whole trajectory as one message (3D panel)",
    "tf": "frame transform map -> <track>/base_link at each pose (attach a model)",
    "covariance": "the 3-sigma position covariance ellipsoid at each step (3D panel)",
    "error": "position error vs the reference, ex/ey/ez/norm in m (Plot panel)",
    "fix": "the estimate in WGS 84 (Map panel; geodetic data only)",
}


def replay(*args, cwd):
    subprocess.run([sys.executable, "-m", "replay.cli", *args], cwd=cwd, check=True, stdout=subprocess.DEVNULL)


def chromium(html_path: Path, png: Path, height: int) -> None:
    exe = next((shutil.which(n) for n in ("chromium", "chromium-browser") if shutil.which(n)), None)
    if exe is None:
        sys.exit("make_screenshots: chromium not found (Debian: apt-get install chromium)")
    work = png.parent / "profile"
    cmd = [
        exe,
        "--headless",
        "--no-sandbox",
        "--disable-gpu",
        "--hide-scrollbars",
        "--no-first-run",
        "--disable-background-networking",
        "--disable-component-update",
        "--disable-sync",
        "--disable-extensions",
        f"--user-data-dir={work}",
        "--host-resolver-rules=MAP * ~NOTFOUND",
        "--virtual-time-budget=5000",
        f"--window-size={WIDTH},{height}",
        f"--screenshot={png}",
        html_path.resolve().as_uri(),
    ]
    subprocess.run(cmd, check=True, capture_output=True, timeout=120)


def small_png(src: Path, dst: Path) -> None:
    """``src`` without its blank bottom, as a 256-colour PNG at ``dst`` (an octree keeps the thin
    lines' palette colours, which a median cut merges)."""
    from PIL import Image, ImageChops

    img = Image.open(src).convert("RGB")
    box = ImageChops.difference(img, Image.new("RGB", img.size, img.getpixel((0, img.height - 1)))).getbbox()
    if box:
        img = img.crop((0, 0, img.width, min(img.height, box[3] + 16)))
    img.quantize(256, method=Image.Quantize.FASTOCTREE).save(dst, optimize=True)
    print(f"wrote {dst.relative_to(ROOT)} ({dst.stat().st_size // 1024} KB)")


def read_mcap(path: Path):
    """(channel rows, {track: (x, y)}, {track: (t, norm)}) read back from the MCAP."""
    from foxglove_schemas_protobuf.PoseInFrame_pb2 import PoseInFrame
    from mcap.reader import make_reader

    rows, xy, err = [], {}, {}
    with open(path, "rb") as fh:
        reader = make_reader(fh)
        summary = reader.get_summary()
        counts = summary.statistics.channel_message_counts
        for cid, ch in sorted(summary.channels.items()):
            schema = summary.schemas[ch.schema_id]
            kind = ch.topic.rsplit("/", 1)[-1]
            what = WHAT.get(
                kind,
                "the sensor's values at its valid samples (Plot panel)"
                if ch.topic.startswith("/sensors/")
                else "identity map -> enu, once",
            )
            if ch.topic.startswith("/replay/reference/"):
                what = what.replace("the estimate's position and heading", "the reference position").replace(
                    "the whole trajectory", "the whole reference trajectory"
                )
            rows.append((ch.topic, f"{schema.name} ({ch.message_encoding})", counts.get(cid, 0), what))
        fh.seek(0)
        for _, ch, msg in make_reader(fh).iter_messages():
            track = ch.topic.split("/")[2] if ch.topic.startswith("/replay/") else None
            if ch.topic.endswith("/pose"):
                p = PoseInFrame.FromString(msg.data).pose.position
                xy.setdefault(track, ([], []))
                xy[track][0].append(p.x)
                xy[track][1].append(p.y)
            elif ch.topic.endswith("/error"):
                e = json.loads(msg.data)
                err.setdefault(track, ([], []))
                err[track][0].append(msg.log_time * 1e-9)
                err[track][1].append(e["norm"] if e["norm"] is not None else float("nan"))
    return rows, xy, err


def tracks_figure(xy, err) -> str:
    """The poses (east-north) and error norms decoded from the MCAP, as a base64 PNG."""
    import numpy as np

    from replay.outputs import plots
    from replay.outputs.palette import Palette

    pal = Palette([t for t in xy if t != "reference"])
    fig, axes = plots.figure(1, 2, figsize=(12.4, 4.2))
    a, b = axes[0]
    for track, (x, y) in xy.items():
        ref = track == "reference"
        a.plot(
            x,
            y,
            color="black" if ref else pal.colour(track),
            ls="--" if ref else "-",
            lw=1.4 if ref else 1,
            label=track,
        )
    a.set(
        xlabel=plots.label("east", "m"),
        ylabel=plots.label("north", "m"),
        title="/replay/<track>/pose, decoded from run.mcap (run 0)",
    )
    a.set_aspect("equal", adjustable="datalim")
    for track, (t, norm) in err.items():
        t = np.asarray(t)
        b.plot(t - t[0], norm, color=pal.colour(track), lw=1, label=track)
    b.set(
        xlabel="t (s)",
        ylabel=plots.label("position error", "m"),
        yscale="log",
        title="/replay/<filter>/error: field norm, decoded from run.mcap",
    )
    for ax in (a, b):
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    fig.subplots_adjust(wspace=0.22)
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=100, bbox_inches="tight")
    return base64.b64encode(buf.getvalue()).decode()


def channels_page(rows, xy, err, out: Path) -> None:
    cells = "\n".join(
        f"<tr><td><code>{html.escape(t)}</code></td><td>{html.escape(s)}</td>"
        f"<td class=n>{n}</td><td>{html.escape(w)}</td></tr>"
        for t, s, n, w in rows
    )
    total = sum(r[2] for r in rows)
    out.write_text(f"""<!doctype html><html><head><meta charset="utf-8"><style>
body {{ font: 13px/1.35 sans-serif; margin: 14px 18px; color: #222 }}
h1 {{ font-size: 17px; margin: 0 0 4px }} p {{ margin: 0 0 8px; color: #555 }}
table {{ border-collapse: collapse; width: 100% }} td, th {{ border-bottom: 1px solid #ddd; padding: 2px 8px;
text-align: left }} th {{ background: #f2f2f2 }} td.n {{ text-align: right }} code {{ font-size: 12px }}
</style></head><body>
<h1>run.mcap: {len(rows)} channels, {total} messages</h1>
<p>Read back from the exported file with the <code>mcap</code> Python reader (summary section and messages);
not a Foxglove Studio screenshot. Export of <code>replay eval sim/auv-sonar --runs 20</code>, run 0.</p>
<table><tr><th>topic</th><th>schema (encoding)</th><th>messages</th><th>what it shows</th></tr>
{cells}</table>
<img src="data:image/png;base64,{tracks_figure(xy, err)}" style="max-width:100%;margin-top:10px">
</body></html>""")


def main() -> None:
    with tempfile.TemporaryDirectory(prefix="replay-shots-") as tmp:
        tmp = Path(tmp)
        replay("eval", "sim/auv-sonar", "--runs", "20", "-o", "run", "-q", cwd=tmp)
        replay("report", "run", cwd=tmp)
        replay("export", "run", "--mcap", "run.mcap", "-q", cwd=tmp)
        chromium(tmp / "run" / "report" / "report.html", tmp / "report_full.png", 2000)
        small_png(tmp / "report_full.png", HERE / "report.png")
        rows, xy, err = read_mcap(tmp / "run.mcap")
        channels_page(rows, xy, err, tmp / "channels.html")
        chromium(tmp / "channels.html", tmp / "channels_full.png", 1200)
        small_png(tmp / "channels_full.png", HERE / "mcap_channels.png")


if __name__ == "__main__":
    main()
