"""The dataset registry: manifests, search order, loading, and no shadowing of `datasets`."""
import os
import subprocess
import sys
import types
from pathlib import Path

import click

from replay.cli import main as replay_main
import numpy as np
import pytest
from click.testing import CliRunner

from replay.data import registry
from replay.util.errors import DataError, ReplayError
from replay.frame import Channel, Frame
from replay.data.registry import Dataset

REPO = Path(__file__).resolve().parents[1]
SHARED = Path(os.environ.get("REPLAY_SHARED", REPO.parent / "shared"))
BOHAI = SHARED / "datasets" / "bohai"

LOCAL = ["20220625_0_0", "20220822_0_0", "20220822_0_3", "20220822_0_4", "20220822_0_5", "20220822_0_6"]
UPSTREAM = ["20210428/1/20210428_1_0.csv", "20220625/0/20220625_0_1.csv", "20220625/0/20220625_0_2.csv",
            "20220625/1/20220625_1_0.csv", "20220712_0_1.csv", "20220719_6_1.csv",
            "20220822/0/20220822_0_1.csv", "20220822/0/20220822_0_2.csv", "20220822/0/20220822_0_7.csv",
            "20220822/0/20220822_0_8.csv", "20230517_0_0.csv"]
# the local six live upstream under <date>/0/
UPSTREAM += [f"{s[:8]}/0/{s}.csv" for s in LOCAL]


@pytest.fixture
def clean_env(monkeypatch, tmp_path):
    """No user data dir, and a private empty cache."""
    monkeypatch.delenv("REPLAY_DATA_DIR", raising=False)
    monkeypatch.setenv("REPLAY_CACHE_DIR", str(tmp_path / "cache"))
    return tmp_path


@pytest.fixture
def fake_adapter(monkeypatch):
    """Replace the adapter lookup with a tiny CSV reader: column `time` -> t."""
    def load(path, **options):
        t = np.loadtxt(path, delimiter=",", skiprows=1, usecols=0, ndmin=1)
        return Frame(t, {"x": Channel(t * 2, "m")}, meta={"options": options})
    monkeypatch.setattr(registry, "_adapter", lambda name: load)


def write_fake(path, n=10):
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text("time,x\n" + "".join(f"{0.1 * i:.1f},{i}\n" for i in range(n)))
    return path


# ---------------------------------------------------------------- manifests

def test_all_bohai_sequences_and_sim_listed():
    known = registry.all_datasets()
    bohai = {i for i in known if i.startswith("bohai/")}
    assert len(bohai) == 17
    assert {ds.upstream_path for ds in known.values() if ds.id.startswith("bohai/")} == set(UPSTREAM)
    assert "sim/auv-sonar" in known
    for ds_id in bohai:
        ds = known[ds_id]
        assert ds.id == "bohai/" + Path(ds.file).stem
        assert ds.adapter == "bohai-csv" and ds.kind == "file"
        assert ds.url == ("https://raw.githubusercontent.com/nature1949/AUV_navigation_dataset/main/"
                          + ds.upstream_path)
        assert ds.upstream_path.endswith(ds.file)
        assert ds.license == "CC0-1.0" and "Electronics" in ds.citation
        assert ds.default_task == "fusion" and ds.description and ds.site


def test_sim_entry():
    ds = registry.get("sim/auv-sonar")
    assert ds.kind == "sim"
    assert ds.generator == "replay.sim.auv_sonar:make_frame"
    assert ds.default_task == "sonar"
    assert ds.file is None and ds.url is None and ds.sha256 is None
    assert registry.locate(ds) is None


def test_checksums_registered_for_the_ten_upstream_sums():
    """10 of 17 registered (replay/data/checksums.py); the six local ones among them."""
    known = registry.all_datasets()
    with_sha = sorted(i for i, ds in known.items() if ds.sha256)
    assert len(with_sha) == 10 and {f"bohai/{s}" for s in LOCAL} <= set(with_sha)
    if not BOHAI.is_dir():
        pytest.skip(f"shared Bohai files not found at {BOHAI} (set REPLAY_SHARED)")
    sums = {}
    for line in (BOHAI / "SHA256SUMS").read_text().splitlines():
        sha, name = line.split()
        sums[name] = sha
    assert len(sums) == 6
    for name, sha in sums.items():
        assert known["bohai/" + Path(name).stem].sha256 == sha


def test_rows_match_readme_table():
    rows = {s: registry.get(f"bohai/{s}").rows for s in LOCAL}
    assert rows == {"20220625_0_0": 8476, "20220822_0_0": 3478, "20220822_0_3": 8500,
                    "20220822_0_4": 7614, "20220822_0_5": 7067, "20220822_0_6": 7509}


def test_unknown_id_suggests_close_match():
    with pytest.raises(ReplayError) as err:
        registry.get("bohai/20220822_07")
    msg = str(err.value)
    assert "bohai/20220822_0_7" in msg and "\n" not in msg
    with pytest.raises(ReplayError, match="did you mean bohai/20220822_0_6"):
        registry.get("20220822_0_6")


def test_bad_manifests_are_rejected(tmp_path):
    (tmp_path / "a.toml").write_text('[[dataset]]\nid = "x/a"\nfile = "a.csv"\nadapter = "bohai-csv"\ncolour = 1\n')
    with pytest.raises(ReplayError, match=r"dataset x/a: colour: unknown key \(known: "):
        registry.all_datasets(tmp_path)
    (tmp_path / "a.toml").write_text('[[dataset]]\nid = "x/a"\nfile = "a.csv"\nadapter = "bohai-csv"\n')
    (tmp_path / "b.toml").write_text('[[dataset]]\nid = "x/a"\ngenerator = "m:f"\n')
    with pytest.raises(ReplayError, match="also defined in"):
        registry.all_datasets(tmp_path)
    (tmp_path / "b.toml").write_text('[[dataset]]\nid = "x/b"\ngenerator = "m:f"\n')
    assert [ds.kind for ds in registry.all_datasets(tmp_path).values()] == ["file", "sim"]


# ---------------------------------------------------------------- locating

def test_locate_flat_upstream_and_prefixed_layouts(clean_env):
    ds = registry.get("bohai/20220822_0_7")
    layouts = {"flat": "20220822_0_7.csv", "upstream": "20220822/0/20220822_0_7.csv",
               "prefixed": "bohai/20220822_0_7.csv", "prefixed-upstream": "bohai/20220822/0/20220822_0_7.csv"}
    for name, rel in layouts.items():
        root = clean_env / name
        write_fake(root / rel)
        assert registry.locate(ds, root) == root / rel
    assert registry.locate(ds, clean_env / "empty") is None


def test_local_ids_lists_the_ids_of_a_prefix_found_locally(clean_env):
    root = clean_env / "data"
    for name in ("20220822_0_7", "20220822_0_5"):
        write_fake(root / f"{name}.csv")
    assert registry.local_ids("bohai/20220822_", root) == ["bohai/20220822_0_5", "bohai/20220822_0_7"]
    assert registry.local_ids("bohai/20220822_0_7", root) == ["bohai/20220822_0_7"]
    assert registry.local_ids("bohai/", clean_env / "empty") == [] and registry.local_ids("sim/", root) == []


def test_locate_root_level_upstream_path(clean_env):
    ds = registry.get("bohai/20220712_0_1")
    assert ds.upstream_path == ds.file == "20220712_0_1.csv"
    assert len(registry.candidates(ds, Path("/r"))) == 2
    write_fake(clean_env / "d" / "bohai" / "20220712_0_1.csv")
    assert registry.locate(ds, clean_env / "d") == clean_env / "d" / "bohai" / "20220712_0_1.csv"


def test_search_order_data_dir_then_env_then_cache(clean_env, monkeypatch):
    ds = registry.get("bohai/20220822_0_0")
    arg, env, cache = clean_env / "arg", clean_env / "env", clean_env / "cache"
    for root in (arg, env, cache / "bohai"):
        write_fake(root / "20220822_0_0.csv")
    monkeypatch.setenv("REPLAY_DATA_DIR", str(env))
    assert registry.search_roots(arg) == [arg, env, cache]
    assert registry.locate(ds, arg) == arg / "20220822_0_0.csv"
    assert registry.locate(ds) == env / "20220822_0_0.csv"
    monkeypatch.delenv("REPLAY_DATA_DIR")
    assert registry.locate(ds) == cache / "bohai" / "20220822_0_0.csv"


def test_cache_dir_follows_xdg(monkeypatch, tmp_path):
    monkeypatch.delenv("REPLAY_CACHE_DIR", raising=False)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    assert registry.cache_dir() == tmp_path / "replay"
    monkeypatch.setenv("REPLAY_CACHE_DIR", str(tmp_path / "mine"))
    assert registry.cache_dir() == tmp_path / "mine"


# ---------------------------------------------------------------- loading

def test_missing_dataset_error_is_one_actionable_line(clean_env):
    (clean_env / "nowhere").mkdir()  # an existing directory without the file (a missing one is refused first)
    with pytest.raises(ReplayError) as err:
        registry.load_frame("bohai/20220822_0_7", data_dir=clean_env / "nowhere")
    msg = str(err.value)
    assert "\n" not in msg
    assert msg.startswith("dataset bohai/20220822_0_7 not found in ")
    assert str(clean_env / "nowhere") in msg and str(clean_env / "cache") in msg
    assert "replay datasets fetch bohai/20220822_0_7" in msg and "--data-dir" in msg


def test_load_frame_checks_sha256_and_flags_a_mismatch(clean_env, fake_adapter):
    path = write_fake(clean_env / "d" / "20220822_0_0.csv", n=10)
    frame = registry.load_frame("bohai/20220822_0_0", data_dir=clean_env / "d", first=4, scale=3)
    assert len(frame) == 4
    assert frame.meta["dataset"] == "bohai/20220822_0_0"
    assert frame.meta["options"] == {"scale": 3}
    assert frame.meta["sha256"] == registry.sha256_file(path)
    assert frame.meta["checksum"] == "mismatch"
    [entry] = frame.report.find("flagged")
    assert entry.what == "20220822_0_0.csv" and entry.count == 1
    assert registry.get("bohai/20220822_0_0").sha256 in entry.reason


def test_load_frame_unknown_checksum_is_not_flagged(clean_env, fake_adapter):
    write_fake(clean_env / "d" / "20220822_0_7.csv", n=5)
    frame = registry.load_frame("bohai/20220822_0_7", data_dir=clean_env / "d")
    assert len(frame) == 5 and frame.meta["checksum"] == "unknown"
    assert frame.report.entries == []


def test_load_frame_plain_csv_path(clean_env, fake_adapter):
    path = write_fake(clean_env / "mine.csv", n=7)
    for arg in (path, str(path)):
        frame = registry.load_frame(arg, first=3)
        assert len(frame) == 3 and frame.meta["dataset"] == str(path)
    with pytest.raises(DataError, match="no such file"):
        registry.load_frame(str(clean_env / "other.csv"))
    (clean_env / "log.xyz").write_text("1\n")
    with pytest.raises(ReplayError, match="cannot tell the file format"):
        registry.load_frame(str(clean_env / "log.xyz"))


def test_load_frame_sim_generator(monkeypatch):
    from replay.sim import generator
    from replay.util.params import Param

    module = types.ModuleType("fake_sim_module")

    @generator((Param("steps", int, 20, "samples", low=1),))
    def make_frame(rng, *, steps):
        t = np.arange(steps) * 0.5
        return Frame(t, {"r": Channel(rng.normal(size=steps), "m")})

    module.make_frame = make_frame
    monkeypatch.setitem(sys.modules, "fake_sim_module", module)
    ds = Dataset(id="sim/fake", kind="sim", generator="fake_sim_module:make_frame")
    a = registry.load_frame(ds, rng=7, steps=30)
    b = registry.load_frame(ds, rng=7, steps=30, first=10)
    assert len(a) == 30 and len(b) == 10
    assert np.array_equal(a.channels["r"].values[:10], b.channels["r"].values)
    assert a.meta["dataset"] == "sim/fake" and a.meta["seed"] == 7
    with pytest.raises(ReplayError, match=r"^dataset 'sim/fake': steps must be an integer >= 1 \(got 2.5\)$"):
        registry.load_frame(ds, rng=7, steps=2.5)
    with pytest.raises(ReplayError, match=r"^dataset 'sim/fake': unknown parameter 'step' \(known: steps\)$"):
        registry.load_frame(ds, rng=7, step=3)
    missing = Dataset(id="sim/none", kind="sim", generator="no_such_module_xyz:make_frame")
    with pytest.raises(ReplayError, match="generator no_such_module_xyz:make_frame is not available"):
        registry.load_frame(missing)
    module.undeclared = lambda rng, steps=20: None
    with pytest.raises(ReplayError, match="declares no parameters"):
        registry.load_frame(Dataset(id="sim/bare", kind="sim", generator="fake_sim_module:undeclared"))


def test_file_dataset_options_are_checked_against_the_adapter(clean_env):
    write_fake(clean_env / "d" / "20220822_0_7.csv", n=5)
    with pytest.raises(ReplayError) as err:
        registry.load_frame("bohai/20220822_0_7", data_dir=clean_env / "d", jump=3.0)
    assert str(err.value) == ("adapter bohai-csv: unknown option 'jump' "
                              "(known: jump_threshold, max_speed, gps_tolerance, gap_factor)")
    assert registry.check_params("bohai/20220822_0_7", {"max_speed": 4.0}) == {"max_speed": 4.0}
    with pytest.raises(ReplayError, match=r"^adapter lake: unknown option 'mapping' \(known: max_gap\)$"):
        registry.check_params(str(clean_env / "x.csv"), {"mapping": "m.toml"}, adapter="lake")


def test_load_real_bohai_file_if_adapter_available(clean_env):
    pytest.importorskip("replay.adapters.bohai", reason="the bohai-csv adapter is not written yet")
    if not BOHAI.is_dir():
        pytest.skip(f"shared Bohai files not found at {BOHAI}")
    frame = registry.load_frame("bohai/20220822_0_0", data_dir=BOHAI, first=100)
    assert len(frame) == 100
    assert frame.meta["dataset"] == "bohai/20220822_0_0" and frame.meta["checksum"] == "verified"


# ---------------------------------------------------------------- the datasets/ folder

def test_datasets_folder_holds_no_python():
    folder = REPO / "datasets"
    assert sorted(p.name for p in folder.iterdir() if p.suffix == ".py") == []
    assert not (folder / "__init__.py").exists()
    assert {p.name for p in folder.glob("*.toml")} >= {"bohai.toml", "sim.toml"}


def test_datasets_folder_never_shadows_a_real_datasets_package(tmp_path):
    pkg = tmp_path / "datasets"
    pkg.mkdir()
    (pkg / "__init__.py").write_text("")
    code = f"import sys; sys.path.append({str(tmp_path)!r}); import datasets; print(datasets.__file__)"
    out = subprocess.run([sys.executable, "-c", code], cwd=REPO, capture_output=True, text=True, check=True)
    assert Path(out.stdout.strip()) == pkg / "__init__.py"


# ---------------------------------------------------------------- CLI



def test_cli_list(clean_env):
    write_fake(clean_env / "d" / "20220822" / "0" / "20220822_0_4.csv")
    result = CliRunner().invoke(replay_main, ["datasets", "list", "--data-dir", str(clean_env / "d")])
    assert result.exit_code == 0, result.output
    lines = result.output.splitlines()
    assert len(lines) == 1 + len(registry.all_datasets())
    assert sum(line.startswith("bohai/") for line in lines) == 17
    row = next(line for line in lines if line.startswith("bohai/20220822_0_4 "))
    assert str(clean_env / "d" / "20220822" / "0" / "20220822_0_4.csv") in row and "7614" in row
    assert "missing" in next(line for line in lines if line.startswith("bohai/20220822_0_7 "))
    assert "generated" in next(line for line in lines if line.startswith("sim/auv-sonar "))
    assert sum(" known " in line for line in lines) == 10


def test_cli_info(clean_env, fake_adapter):
    runner = CliRunner()
    result = runner.invoke(replay_main, ["datasets", "info", "bohai/20220822_0_7"])
    assert result.exit_code == 0, result.output
    assert "location:       missing" in result.output
    assert "replay datasets fetch bohai/20220822_0_7" in result.output
    write_fake(clean_env / "d" / "20220822_0_0.csv", n=6)
    result = runner.invoke(replay_main, ["datasets", "info", "bohai/20220822_0_0", "--data-dir", str(clean_env / "d")])
    assert result.exit_code == 0, result.output
    assert "samples 6, span 0.5 s" in result.output
    assert "flagged        1  20220822_0_0.csv" in result.output
    assert "checksum: mismatch" in result.output
    result = runner.invoke(replay_main, ["datasets", "info", "bohai/nope"])
    assert result.exit_code == 2 and result.output.count("\n") == 1
