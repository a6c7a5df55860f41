"""Nothing is imported from a name in a data file before the name is allowed (issue 33, item 9): a
campaign file or a ``tuned.toml`` naming a filter or task ``package.module:Class`` is refused in one
line before the module is imported, unless ``--allow-module package.module`` (``replay rerun``'s rule,
:func:`replay.util.plugins.refuse_unallowed`, one rule for all three)."""
from __future__ import annotations

import sys

import pytest
from hostile import invoke, message_lines, register

from replay.campaign import spec
from replay.tune.tuned import tuned_params
from replay.util.errors import ReplayError

register("campaign-file-names-unallowed-module", "tuned-toml-names-unallowed-module",
         "campaign-task-names-unallowed-module", "campaign-tune-names-unallowed-module")

MODULE = "replay_marker_plugin_33"
CAMPAIGN = """[campaign]
runs = 2
[[dataset]]
id = "sim/auv-sonar"
params = {{ steps = 20 }}
{extra}
"""


@pytest.fixture
def plugin(tmp_path, monkeypatch):
    """A module that writes a marker file when it is imported (and is no filter)."""
    marker = tmp_path / "imported"
    (tmp_path / "mods").mkdir()
    (tmp_path / "mods" / f"{MODULE}.py").write_text(f"open({str(marker)!r}, 'w').close()\nclass Thing:\n    pass\n")
    monkeypatch.syspath_prepend(str(tmp_path / "mods"))
    yield marker
    sys.modules.pop(MODULE, None)
    from replay.filters import FILTERS
    from replay.tasks import TASKS

    FILTERS.refresh()  # the refused load is remembered as a problem (replay list prints it): not for other tests
    TASKS.refresh()


@pytest.mark.parametrize(
    "extra, key",
    [
        (f'[[filter]]\nname = "{MODULE}:Thing"', "name"),
        (f'[[filter]]\nname = "ekf"\n[task."{MODULE}:Thing"]\nx = 1', "task"),
        (f'[[filter]]\nname = "ekf"\n[tune]\nfilters = ["{MODULE}:Thing"]', "filters"),
    ],
)
def test_campaign_file_naming_a_module_never_imports_it(tmp_path, plugin, extra, key):
    path = tmp_path / "c.toml"
    path.write_text(CAMPAIGN.format(extra=extra))
    with pytest.raises(ReplayError) as err:
        spec.load(path)
    msg = str(err.value)
    assert msg.startswith(f"{path}:") and f": {key}: " in msg and f"--allow-module {MODULE}" in msg
    assert not plugin.exists() and MODULE not in sys.modules


def test_campaign_file_module_allowed_is_imported(tmp_path, plugin):
    """The control: allowed, the module is imported (and then refused as no filter, in one line)."""
    path = tmp_path / "c.toml"
    path.write_text(CAMPAIGN.format(extra=f'[[filter]]\nname = "{MODULE}:Thing"'))
    with pytest.raises(ReplayError, match="not a subclass"):
        spec.load(path, allow_modules=(MODULE,))
    assert plugin.exists()


def test_cli_campaign_run_and_eval_tuned_refuse_in_one_line_without_importing(tmp_path, plugin):
    path = tmp_path / "tuned.toml"
    path.write_text(CAMPAIGN.format(extra=f'[[filter]]\nname = "{MODULE}:Thing"'))
    for args in (["campaign", "run", str(path), "--out", str(tmp_path / "out"), "-w", "1"],
                 ["eval", "sim/auv-sonar", "--tuned", str(path), "--out", str(tmp_path / "ev")]):
        r = invoke(args)
        lines = message_lines(r.stderr)
        assert r.exit_code != 0 and len(lines) == 1, r.stderr
        assert f"would import the module {MODULE}" in lines[0] and f"--allow-module {MODULE}" in lines[0]
        assert not plugin.exists() and MODULE not in sys.modules
    with pytest.raises(ReplayError, match=f"--tuned loads only built-in"):
        tuned_params(path)
    assert not plugin.exists()
