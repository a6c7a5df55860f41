#!/usr/bin/env bash
# The example plugin and the quickstart notebook (issue 15), against the shared data beside
# the checkout: install examples/replay-plugin-example, run its filter next to the built-in
# ones on a Bohai sequence, on sim/auv-sonar and on its own dataset (its rows on the same
# leaderboard), then execute examples/quickstart.ipynb and examples/scoring.ipynb top to bottom
# (a failing cell fails).
# Uses the checkout's .venv (`.ci/run` makes it); the plugin is uninstalled again at the end
# unless it was installed before.
set -euo pipefail
cd "$(dirname "$0")/.."
PY=.venv/bin/python
REPLAY=.venv/bin/replay
tmp=$(mktemp -d)
had=0
"$PY" -m pip show -q replay-plugin-example >/dev/null 2>&1 && had=1
cleanup() {
  rm -rf "$tmp"
  if [ "$had" = 0 ]; then  # as before: not installed, and no metadata left in the source tree
    "$PY" -m pip uninstall -q -y replay-plugin-example >/dev/null 2>&1 || true
    rm -rf examples/replay-plugin-example/src/*.egg-info examples/replay-plugin-example/build
  fi
}
trap cleanup EXIT

"$PY" -m pip install -q -e examples/replay-plugin-example
listed=$("$REPLAY" list filters example-filter)
grep -F "(plugin: replay-plugin-example 0.1.0)" <<<"$listed"
"$REPLAY" eval bohai/20220822_0_6 --data-dir ../shared/datasets/bohai --filters ukf,example-filter --runs 5 \
  -o "$tmp/bohai"
"$REPLAY" eval sim/auv-sonar --filters ukf,example-filter --runs 5 -o "$tmp/sonar"
"$REPLAY" eval example/range-bearing --filters ekf,ukf,example-filter --runs 5 -o "$tmp/example"
for d in bohai sonar example; do  # the plugin's row beside the built-ins' on each leaderboard
  rows=$(tail -n +2 "$tmp/$d/leaderboard.csv" | cut -d, -f3 | paste -sd, -)
  case ",$rows," in
    *,example-filter,*) echo "CI: $d leaderboard rows: $rows" ;;
    *) echo "CI: the $d leaderboard lacks example-filter (rows: $rows)" >&2; exit 1 ;;
  esac
done
# the notebook, into a scratch copy (the committed one is left as it is)
"$PY" examples/run_notebook.py examples/quickstart.ipynb -o "$tmp/quickstart.ipynb"
# scoring from Python (replay.score on evo's ROS_example.bag), likewise into a scratch copy
"$PY" examples/run_notebook.py examples/scoring.ipynb -o "$tmp/scoring.ipynb"
