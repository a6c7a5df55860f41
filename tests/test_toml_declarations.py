"""Each kind of TOML file is validated from its one declaration (replay.util.tomlschema): the cases below are
generated from the declarations, so a key added to one is tested here without a new line. For every table of
a kind: an undeclared key, each required key removed, each declared key given a value of a wrong type ->
one line naming the file, the table and the key."""

import copy

import pytest
import tomli_w

from adapters.mapping import CHANNEL, ESTIMATE, MAPPING, PARAMS, REFERENCE, from_dict
from replay.campaign import spec
from replay.tune import space
from replay.tune.tuned import tuned_params
from replay.util.errors import ReplayError
from replay.util.params import Param
from replay.util.tomlschema import Each, Table, Value

MAP_DOC = {
    "channels": {"gps": {"topic": "/fix"}},
    "reference": {"position": {"topic": "/fix"}},
    "estimates": {"slam": {"topic": "/odom"}},
    "params": {},
}
MAP_TABLES = [  # (declaration, the table's path in MAP_DOC, its title in messages)
    (MAPPING, (), ""),
    (CHANNEL, ("channels", "gps"), "[channels] gps"),
    (REFERENCE, ("reference", "position"), "[reference] position"),
    (ESTIMATE, ("estimates", "slam"), "[estimates] slam"),
    (PARAMS, ("params",), "[params]"),
]
CAMP_DOC = {
    "campaign": {"runs": 2},
    "dataset": [{"id": "sim/linear"}],
    "filter": [{"name": "kf"}],
    "tune": {"split": {"seeds": 0}},
    "fault": [{"channel": "gps", "kind": "outage"}],
}
CAMP_TABLES = [
    (spec.FILE, (), ""),
    (spec.CAMPAIGN, ("campaign",), "[campaign]"),
    (spec.DATASET, ("dataset", 0), "[[dataset]]"),
    (spec.FILTER, ("filter", 0), "[[filter]]"),
    (spec.TUNE, ("tune",), "[tune]"),
    (spec.FAULT, ("fault", 0), "[[fault]]"),
]


def _wrong(decl):
    """A value of a type ``decl`` does not accept."""
    accepts_str = (decl.type is str) if isinstance(decl, Param) else (str in decl.types)
    return 12345 if accepts_str else "x"


def _cases(tables, doc):
    """(case id, mutated document, substring the one line must hold) from the declarations."""
    for table, path, title in tables:
        head = f"{title}: " if title else ""

        def mutated(change, path=path):
            d = copy.deepcopy(doc)
            node = d
            for p in path:
                node = node[p]
            change(node)
            return d

        if not table.open:
            yield f"{table.name}-unknown", mutated(lambda t: t.update(zzz_typo=1)), f"{head}zzz_typo: unknown key"
        for key in table.required:
            yield f"{table.name}-{key}-missing", mutated(lambda t, k=key: t.pop(k, None)), f"{head}{key}: missing"
        for decl in table.keys:
            if isinstance(decl, (Param, Value)):
                bad = _wrong(decl)
                text = f"{head}{decl.name} must be {decl.accepts()}"
                yield f"{table.name}-{decl.name}-type", mutated(lambda t, k=decl.name, v=bad: t.update({k: v})), text
            elif isinstance(decl, (Table, Each)):
                yield f"{table.name}-{decl.name}-type", mutated(lambda t, k=decl.name: t.update({k: 7})), decl.name
            if isinstance(decl, Each):  # an entry that is not a table
                entry, bad = decl.entry, [7] if decl.array else {"n": 7}
                want = f"{entry.title.format(name='n')}: expected {entry.expect}"
                yield f"{table.name}-{decl.name}-entry", mutated(lambda t, k=decl.name, v=bad: t.update({k: v})), want


def _one_line(err: ReplayError, name: str, want: str) -> None:
    line = str(err)
    assert "\n" not in line and name in line and want in line, (line, want)


def test_every_table_of_each_kind_is_declared_and_reached():
    """The tables the cases walk are every table the declarations hold (none left untested)."""
    def tables(t: Table):
        out = [t]
        for k in t.keys:
            out += tables(k) if isinstance(k, Table) else tables(k.entry) if isinstance(k, Each) else []
        return out

    assert {t.title for t in tables(MAPPING)} == {"", "[channels] {name}", "[reference] {name}",
                                                 "[estimates] {name}", "[params]"}
    assert {id(t) for t in tables(spec.FILE)} == {id(t) for t, _, _ in CAMP_TABLES} | {id(spec.FILE.known()["task"].entry)}
    assert spec.SECTIONS == ("campaign", "dataset", "task", "filter", "tune", "fault")


@pytest.mark.parametrize("case", list(_cases(MAP_TABLES, MAP_DOC)), ids=lambda c: c[0])
def test_mapping_errors_come_from_its_declaration(case):
    _, doc, want = case
    from_dict(MAP_DOC, "m.toml")  # the unmutated document is valid
    with pytest.raises(ReplayError) as err:
        from_dict(doc, "m.toml")
    _one_line(err.value, "m.toml: ", want)


@pytest.mark.parametrize("case", list(_cases(CAMP_TABLES, CAMP_DOC)), ids=lambda c: c[0])
def test_campaign_and_tuned_file_errors_come_from_their_declaration(case, tmp_path):
    _, doc, want = case
    path = tmp_path / "c.toml"
    path.write_text(tomli_w.dumps(doc))
    with pytest.raises(ReplayError) as err:
        spec.load(path)
    _one_line(err.value, f"{path}:", want)
    with pytest.raises(ReplayError) as err:  # a tuned file is a campaign file: the same declaration
        tuned_params(path)
    _one_line(err.value, f"--tuned {path}:", want)


def test_the_campaign_error_names_the_line_of_the_key(tmp_path):
    path = tmp_path / "c.toml"
    path.write_text('[campaign]\nruns = 2\nsede = 1\n[[dataset]]\nid = "sim/linear"\n[[filter]]\nname = "kf"\n')
    with pytest.raises(ReplayError, match=r"c\.toml:3: \[campaign\]: sede: unknown key \(known: alignment, "):
        spec.load(path)


@pytest.mark.parametrize("bad, want", [({"kf": 3}, "kf: expected FILTER.PARAM = SPEC"),
                                        ({"kf": {"q_scale": "log[1e-3, 1]"}}, None)])
def test_search_space_errors_come_from_its_declaration(tmp_path, bad, want):
    path = tmp_path / "s.toml"
    path.write_text(tomli_w.dumps(bad))
    if want is None:
        assert space.entries_from_file(path) == [("kf.q_scale", "log[1e-3, 1]", f"{path}: kf.q_scale")]
        return
    with pytest.raises(ReplayError) as err:
        space.entries_from_file(path)
    _one_line(err.value, f"{path}: ", want)


def test_the_manifest_declaration_is_the_dataset_record_and_drives_its_errors(tmp_path):
    """A dataset manifest's [[dataset]] entry is declared by the fields of registry.Dataset (one place):
    an unknown key, and each declared key given a wrong type, is one line naming the manifest and the id."""
    from replay.data import registry

    assert set(registry.MANIFEST.known()) == registry.MANIFEST_KEYS
    good = {"id": "x/a", "generator": "m:f"}
    assert registry._make_dataset(tmp_path / "m.toml", dict(good)).kind == "sim"
    cases = [("zzz_typo", 1, "zzz_typo: unknown key")]
    cases += [(p.name, _wrong(p), f"{p.name} must be {p.accepts()}") for p in registry.MANIFEST.keys if p.name != "id"]
    cases += [("size", 0, "size must be an integer >= 1"), ("rows", -1, "rows must be an integer >= 0")]
    for key, bad, want in cases:
        with pytest.raises(ReplayError) as err:
            registry._make_dataset(tmp_path / "m.toml", {**good, key: bad})
        _one_line(err.value, f"{tmp_path / 'm.toml'}: dataset x/a: ", want)
