"""Hostile inputs to ``replay score`` and to the inputs of ``replay eval`` (issue 23, items 7, 10, 12, 13).

* Column layouts are decided by the header's names, never by position alone: an x-first CSV
  (``#timestamp,x,y,z,qx,qy,qz,qw``) gives the numbers of the same poses as a TUM file, and a
  CSV whose order nothing tells is refused naming the choices.
* ``--plot`` / ``-o``: an unsupported extension or a location where nothing can be created is
  one line before any computation; missing parent directories are created, files written whole.
* FIFOs and devices are refused before they are read (trajectory files, mappings, datasets).
* An unknown ``recorded:NAME`` is refused from the mapping before the recording is read.
* Mapping channel names must be plain identifiers (they become topic names).
"""
from __future__ import annotations

import os
import signal
import subprocess
import sys
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from hostile import assert_ok, assert_refused, register

register("score-csv-x-first-by-header", "score-csv-headerless-ambiguous", "score-columns-contradict-header",
         "score-columns-misread-euroc-reference", "score-format-contradicts-header",
         "score-tum-w-first-header", "score-ns-stamps-without-unit", "score-boot-stamps-without-unit", "score-time-unit-contradicts-header",
         "score-header-duplicate-column", "score-header-euler-angles", "score-header-millimetres",
         "score-header-unknown-time-unit", "score-plot-docx", "score-plot-no-extension",
         "score-plot-unwritable", "score-plot-parent-is-file", "score-out-new-directory", "score-out-long-name", "score-out-device-link", "score-out-fifo",
         "score-out-symlink-kept",
         "score-fifo", "score-char-device", "score-fifo-in-bag-directory", "eval-dataset-fifo", "eval-mapping-fifo", "eval-mapping-char-device",
         "eval-recorded-unknown-before-reading", "mapping-channel-path", "mapping-channel-newline",
         "mapping-estimate-newline", "mapping-estimate-none")

N = 300
T0 = 1403636579.0


@pytest.fixture(scope="module")
def poses():
    """(t, reference p, q, estimate p, q): a helix; the estimate rotated by ~0.06 deg rms per pose."""
    rng = np.random.default_rng(7)
    s = np.arange(N) * 0.1
    t = T0 + s
    p = np.column_stack([10 * np.cos(s / 4), 10 * np.sin(s / 4), s / 5])
    q = Rotation.from_euler("xyz", np.column_stack([0.1 * np.sin(s), 0.05 * np.cos(s), s / 4])).as_quat()
    qe = (Rotation.from_rotvec(rng.normal(0, 0.0006, (N, 3))) * Rotation.from_quat(q)).as_quat()
    pe = p + rng.normal(0, 0.01, (N, 3))
    return t, p, q, pe, qe


def lines(t, p, q, sep=",", w_first=False, stamp=lambda v: f"{v:.17g}"):
    qq = q[:, [3, 0, 1, 2]] if w_first else q
    return "".join(sep.join([stamp(a), *(f"{v:.17g}" for v in (*b, *c))]) + "\n" for a, b, c in zip(t, p, qq))


@pytest.fixture()
def files(tmp_path, poses):
    t, p, q, pe, qe = poses
    (tmp_path / "ref.tum").write_text(lines(t, p, q, " "))
    (tmp_path / "est.tum").write_text(lines(t, pe, qe, " "))
    return tmp_path


def rotation_rmse(args) -> float:
    out = assert_ok(["score", *args, "-r", "angle_deg"]).stdout
    return float(next(ln.split()[1] for ln in out.splitlines() if ln.strip().startswith("rmse")))


# ---------------------------------------------------------------- item 7: layouts by the header's names


def test_x_first_csv_is_read_by_its_header_names(files, poses):
    t, _, _, pe, qe = poses
    (files / "est.csv").write_text("#timestamp,x,y,z,qx,qy,qz,qw\n" + lines(t, pe, qe))
    tum = rotation_rmse([files / "ref.tum", files / "est.tum"])
    csv = rotation_rmse([files / "ref.tum", files / "est.csv"])
    assert 0.03 < tum < 0.2  # the 0.05-degree class of the case, not 143 degrees
    assert csv == tum
    # the same file read w first (what the EuRoC sniffing did) is the wrong answer this guards against
    from replay.trajectory import load, make, score

    w_first = make(t, pe, qe[:, [1, 2, 3, 0]], source="w-first")  # columns 4..7 taken as w, x, y, z
    wrong = score(load(str(files / "ref.tum")), w_first, relations=["angle_deg"]).stats("ape", "angle_deg")["rmse"]
    assert wrong > 10
    # and --columns by index that contradict the header's names are refused, not followed
    assert_refused(["score", files / "ref.tum", files / "est.csv", "--columns", "t=0,x=1,y=2,z=3,qw=4,qx=5,qy=6,qz=7"],
                   r"est\.csv: --columns qw=4, but the header names column 4 'qx' and qw 'qw'")


def test_one_columns_option_cannot_misread_an_euroc_reference(files, poses):
    t, p, q, pe, qe = poses
    head = "#timestamp, p_RS_R_x [m], p_RS_R_y [m], p_RS_R_z [m], q_RS_w [], q_RS_x [], q_RS_y [], q_RS_z []\n"
    (files / "gt.csv").write_text(head + lines(t, p, q, w_first=True, stamp=lambda v: f"{round(v * 1e9)}"))
    (files / "est.csv").write_text(lines(t, pe, qe))  # no header: x first, but nothing says so
    assert_refused(["score", files / "gt.csv", files / "est.csv"], r"est\.csv: cannot tell the column order")
    assert_refused(["score", files / "gt.csv", files / "est.csv", "--columns", "t=0,x=1,y=2,z=3,qx=4,qy=5,qz=6,qw=7"],
                   r"gt\.csv: --columns qx=4, but the header names column 4 'q_RS_w \[\]' and qx 'q_RS_x \[\]'")


def test_header_after_a_comment_line_is_found(files, poses):
    t, _, _, pe, qe = poses
    (files / "est.csv").write_text("# exported by a tool, v1\ntimestamp,x,y,z,qx,qy,qz,qw\n" + lines(t, pe, qe))
    assert rotation_rmse([files / "ref.tum", files / "est.csv"]) == rotation_rmse([files / "ref.tum", files / "est.tum"])


def test_euroc_names_keep_w_first_and_nanoseconds(files, poses):
    t, _, _, pe, qe = poses
    head = "#timestamp, p_RS_R_x [m], p_RS_R_y [m], p_RS_R_z [m], q_RS_w [], q_RS_x [], q_RS_y [], q_RS_z []\n"
    (files / "data.csv").write_text(head + lines(t, pe, qe, w_first=True, stamp=lambda v: f"{round(v * 1e9)}"))
    assert rotation_rmse([files / "ref.tum", files / "data.csv"]) == pytest.approx(
        rotation_rmse([files / "ref.tum", files / "est.tum"]), rel=1e-9)


def test_headerless_csv_of_eight_columns_is_refused_with_the_choices(files, poses):
    t, _, _, pe, qe = poses
    (files / "est.csv").write_text(lines(t, pe, qe))
    line = assert_refused(["score", files / "ref.tum", files / "est.csv"], r"est\.csv: cannot tell the column order")
    assert "--format euroc" in line and "--columns t=0,x=1,y=2,z=3,qx=4,qy=5,qz=6,qw=7" in line
    ok = rotation_rmse([files / "ref.tum", files / "est.csv", "--columns", "t=0,x=1,y=2,z=3,qx=4,qy=5,qz=6,qw=7"])
    assert ok == rotation_rmse([files / "ref.tum", files / "est.tum"])


def test_format_that_contradicts_the_header_is_refused(files, poses):
    t, _, _, pe, qe = poses
    (files / "est.csv").write_text("#timestamp,x,y,z,qx,qy,qz,qw\n" + lines(t, pe, qe))
    assert_refused(["score", files / "est.csv", files / "est.csv", "--format", "euroc"],
                   r"est\.csv: --format euroc reads .* but the header names timestamp, x, y, z, qx, qy, qz, qw")


def test_space_separated_w_first_header_is_not_read_as_tum(files, poses):
    t, _, _, pe, qe = poses
    (files / "est.txt").write_text("# t x y z qw qx qy qz\n" + lines(t, pe, qe, " ", w_first=True))
    tum = rotation_rmse([files / "ref.tum", files / "est.tum"])
    assert rotation_rmse([files / "ref.tum", files / "est.txt"]) == tum
    assert_refused(["score", files / "ref.tum", files / "est.txt", "--format", "tum"],
                   r"est\.txt: --format tum reads .* but the header names t, x, y, z, qw")
    (files / "est.txt").rename(files / "w.tum")
    assert_refused(["score", files / "ref.tum", files / "w.tum"],
                   r"w\.tum: the extension \.tum reads .* but the header names t, x, y, z, qw.*give --format csv")
    assert rotation_rmse([files / "w.tum", files / "w.tum", "--format", "csv"]) == 0


def test_time_unit_from_the_header_or_unix_time_else_refused(files, poses):
    t, p, q, pe, qe = poses
    ns = lambda v: f"{round(v * 1e9)}"  # noqa: E731
    tum = rotation_rmse([files / "ref.tum", files / "est.tum"])
    # the case: x-first CSV, '#timestamp' without unit, Unix time in ns, against a TUM reference
    (files / "est.csv").write_text("#timestamp,x,y,z,qx,qy,qz,qw\n" + lines(t, pe, qe, stamp=ns))
    assert rotation_rmse([files / "ref.tum", files / "est.csv"]) == pytest.approx(tum, rel=1e-9)
    # stamps since boot in ns (2e4 s): no unit says so and they are not Unix time: refused
    boot = lambda v: f"{round((v - T0 + 2e4) * 1e9)}"  # noqa: E731
    (files / "ref.csv").write_text("timestamp,x,y,z,qx,qy,qz,qw\n" + lines(t, p, q, stamp=boot))
    (files / "boot.csv").write_text("timestamp,x,y,z,qx,qy,qz,qw\n" + lines(t, pe, qe, stamp=boot))
    assert_refused(["score", files / "ref.csv", files / "boot.csv"],
                   r"ref\.csv: the time column 'timestamp' names no unit .* give --time-unit")
    assert rotation_rmse([files / "ref.csv", files / "boot.csv", "--time-unit", "ns"]) == pytest.approx(tum, rel=1e-9)
    (files / "est2.csv").write_text("timestamp [ns],x,y,z,qx,qy,qz,qw\n" + lines(t, pe, qe, stamp=ns))
    assert_refused(["score", files / "est2.csv", files / "est2.csv", "--time-unit", "s"],
                   r"est2\.csv: --time-unit s, but the header's time column 'timestamp \[ns\]' says ns")


@pytest.mark.parametrize("head,match", [
    ("t,x,y,z,x,y,z,w", r"the header names 'x' twice"),
    ("time,x,y,z,roll,pitch,yaw,extra", r"the header names angles \(roll, pitch, yaw\).*--columns"),
    ("t,x [mm],y [mm],z [mm],qx,qy,qz,qw", r"the header's position column 'x \[mm\]' is not in metres"),
    ("time [h],x,y,z,qx,qy,qz,qw", r"the header's time column 'time \[h\]' gives the unknown unit 'h'"),
])
def test_header_that_cannot_decide_is_refused(files, poses, head, match):
    t, _, _, pe, qe = poses
    (files / "est.csv").write_text(head + "\n" + lines(t, pe, qe))
    assert_refused(["score", files / "ref.tum", files / "est.csv"], r"est\.csv: " + match)


# ---------------------------------------------------------------- item 10: -o and --plot


@pytest.mark.parametrize("name,match", [
    ("x.docx", r"--plot .*x\.docx: unsupported extension '\.docx' \(supported: \.png, \.pdf, \.svg, \.eps\)"),
    ("x", r"--plot .*x: unsupported extension none"),
])
def test_plot_extension_refused_before_computing(files, name, match):
    assert_refused(["score", files / "ref.tum", files / "est.tum", "--plot", files / name], match)
    assert not (files / name).exists()


def test_unwritable_locations_refused_before_computing(files):
    if os.path.isdir("/proc"):
        assert_refused(["score", files / "ref.tum", files / "est.tum", "--plot", "/proc/x.png"],
                       r"--plot /proc/x\.png: lies in /proc \(devices and kernel files\), not a place for an output")
    (files / "null.csv").symlink_to(os.devnull)  # as -o /dev/stdout: a rename would replace the link itself
    assert_refused(["score", files / "ref.tum", files / "est.tum", "-o", files / "null.csv"],
                   r"--out .*null\.csv: lies in /dev")
    assert (files / "null.csv").is_symlink()
    os.mkfifo(files / "pipe.csv")
    assert_refused(["score", files / "ref.tum", files / "est.tum", "-o", files / "pipe.csv"],
                   r"--out .*pipe\.csv: a FIFO \(named pipe\), not a regular file: refusing to replace it")
    assert_refused(["score", files / "ref.tum", files / "est.tum", "-o", files / "ref.tum" / "x.csv"],
                   r"--out .*ref\.tum/x\.csv: .*ref\.tum is not a directory")
    assert_refused(["score", files / "ref.tum", files / "est.tum", "-o", "a" * 300 + ".csv"],
                   r"--out a+\.\.\.: a name of 304 bytes in this path is too long")


def test_output_parents_are_created_and_files_written_whole(files):
    out, plot = files / "new" / "deep" / "board.csv", files / "figs" / "p.png"
    assert_ok(["score", files / "ref.tum", files / "est.tum", "-o", out, "--plot", plot])
    rows = out.read_text().splitlines()
    assert rows[0].startswith("dataset,task,filter") and "recorded:est" in rows[1] and len(rows) == 2
    assert plot.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert sorted(os.listdir(out.parent)) == ["board.csv"]
    assert sorted(os.listdir(plot.parent)) == ["p.png", "p_map.png", "p_rpy.png", "p_xyz.png"]  # replay.trajectory.plot
    (files / "kept.csv").write_text("old\n")
    (files / "link.csv").symlink_to("kept.csv")  # a link keeps pointing where it did; its target is replaced
    assert_ok(["score", files / "ref.tum", files / "est.tum", "-o", files / "link.csv"])
    assert (files / "link.csv").is_symlink() and (files / "kept.csv").read_text() == out.read_text()



def test_dev_shm_holds_outputs_but_a_link_from_it_to_a_device_is_refused():
    """/dev/shm is a RAM file system of regular files (the suite's scratch space, tests/conftest.py), not
    a device: an output may go there; a link there to /dev/null is refused as any other."""
    import tempfile

    from replay.util import outfile
    from replay.util.errors import ReplayError

    if not os.path.isdir("/dev/shm") or not os.access("/dev/shm", os.W_OK):
        pytest.skip("no writable /dev/shm")
    with tempfile.TemporaryDirectory(dir="/dev/shm") as d:
        assert outfile.check(Path(d) / "board.csv", "--out") == Path(d) / "board.csv"
        (Path(d) / "null.csv").symlink_to(os.devnull)
        with pytest.raises(ReplayError, match=r"--out .*null\.csv: lies in /dev \(devices and kernel files\)"):
            outfile.check(Path(d) / "null.csv", "--out")
    with pytest.raises(ReplayError, match=r"--out /dev/x\.csv: lies in /dev"):
        outfile.check("/dev/x.csv", "--out")

# ---------------------------------------------------------------- item 12: FIFOs, devices, early refusals


@contextmanager
def deadline(seconds=30):
    """Fail instead of hanging if a FIFO is opened or read after all."""
    def boom(*_):
        raise TimeoutError("blocked on a FIFO")
    old = signal.signal(signal.SIGALRM, boom)
    signal.alarm(seconds)
    try:
        yield
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, old)


def test_fifo_trajectory_mapping_and_dataset_refused_unread(files):
    for name in ("fifo.txt", "fifo.csv", "map.toml"):
        os.mkfifo(files / name)
    (files / "x.bag").write_bytes(b"not a bag")
    with deadline():
        assert_refused(["score", files / "ref.tum", files / "fifo.txt"],
                       r"fifo\.txt: a FIFO \(named pipe\), not a regular file: refusing to read it")
        assert_refused(["eval", files / "fifo.csv", "--filters", "ekf", "--out", files / "o"],
                       r"fifo\.csv: a FIFO \(named pipe\), not a regular file: refusing to read it as a dataset")
        assert_refused(["eval", files / "x.bag", "--mapping", files / "map.toml", "--filters", "none",
                        "--out", files / "o"], r"map\.toml: a FIFO \(named pipe\), not a regular file")
        (files / "bag").mkdir()
        (files / "bag" / "metadata.yaml").write_text("rosbag2_bagfile_information: {}\n")
        os.mkfifo(files / "bag" / "bag_0.mcap")
        assert_refused(["score", f"{files / 'bag'}:/ref", f"{files / 'bag'}:/est"],
                       r"bag_0\.mcap: a FIFO \(named pipe\), not a regular file: refusing to read it as a file of")


def test_char_device_refused_unread(files):
    """In a subprocess with a timeout: reading /dev/zero would never end."""
    if not os.path.exists("/dev/zero"):
        pytest.skip("no /dev/zero")
    (files / "x.bag").write_bytes(b"not a bag")
    code = ("import sys; from replay.cli import main; sys.argv = ['replay'] + sys.argv[1:]; main()")
    for args, match in ((["score", "/dev/zero", str(files / "ref.tum")], "/dev/zero: a character device"),
                        (["eval", str(files / "x.bag"), "--mapping", "/dev/zero", "--filters", "none", "--out",
                          str(files / "o")], "/dev/zero: a character device, not a regular file")):
        res = subprocess.run([sys.executable, "-c", code, *args], capture_output=True, text=True, timeout=120)
        assert res.returncode == 2 and match in res.stderr and len(res.stderr.strip().splitlines()) == 1, res.stderr


ESTIMATES_MAP = ('[channels]\ngps = "/fix"\n[reference]\nposition = "/fix"\n'
                 '[estimates]\nslam = "/slam"\n')


def test_unknown_recorded_estimate_refused_before_the_recording_is_read(files):
    (files / "x.bag").write_bytes(b"not a bag: reading it would fail with another error")
    (files / "m.toml").write_text(ESTIMATES_MAP)
    assert_refused(["eval", files / "x.bag", "--mapping", files / "m.toml", "--filters", "none,recorded:nope",
                    "--out", files / "o"], r"x\.bag: no recorded estimate 'nope' \(the mapping's \[estimates\] "
                                           r"declare: slam\)")
    from replay import evaluate
    from replay.util.errors import ReplayError

    with pytest.raises(ReplayError, match="no recorded estimate 'nope'"):
        evaluate(str(files / "x.bag"), filters=["recorded:nope"], dataset_params={"mapping": str(files / "m.toml")})


# ---------------------------------------------------------------- item 13: mapping names


@pytest.mark.parametrize("mapping,match", [
    ('[channels]\n"../../evil" = "/fix"\n', r"\[channels\] '\.\./\.\./evil': a channel name is a letter"),
    ('[channels]\n"gps\\nx" = "/fix"\n', r"\[channels\] 'gps\\nx': a channel name is a letter"),
    ('[channels]\ngps = "/fix"\n[reference]\n"pos/x" = "/fix"\n', r"\[reference\] 'pos/x': a channel name"),
    ('[channels]\ngps = "/fix"\n[reference]\nposition = "/fix"\n[estimates]\n"orb\\n" = "/s"\n',
     r"\[estimates\] 'orb\\n': a name of letters"),
    ('[channels]\ngps = "/fix"\n[reference]\nposition = "/fix"\n[estimates]\nnone = "/s"\n',
     r"\[estimates\] 'none': .*not 'none'"),
])
def test_mapping_names_that_are_not_plain_are_refused(files, mapping, match):
    (files / "x.bag").write_bytes(b"not a bag")
    (files / "m.toml").write_text(mapping)
    line = assert_refused(["eval", files / "x.bag", "--mapping", files / "m.toml", "--filters", "ekf",
                           "--out", files / "o"], r"m\.toml: " + match)
    assert "\n" not in line
