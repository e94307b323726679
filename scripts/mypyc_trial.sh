#!/usr/bin/env bash
# A trial of mypyc (mypy's compiler, in the dev tools already): the localization and
# the catenary (the per-message path's float arithmetic: the drone's and six sigma points'
# catenary solves) compiled from their own type annotations, no second implementation, and
# the stages timed compiled and not, alternately, by benchmarks.bench_pipeline --quick.
# Needs gcc and the Python headers.   scripts/mypyc_trial.sh   (~2 min on 2 cores)
# Results: docs/service_profile.md, section 7.
set -euo pipefail
repo=$(cd "$(dirname "$0")/.." && pwd)
py="$repo/.venv/bin/python"
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
git clone -q "$repo" "$work/src"
git clone -q "$repo" "$work/plain"  # the same code, not compiled
cd "$work/src"
# What mypyc refuses, rewritten for the trial only: the per-message construction tricks that
# fill a frozen dataclass's __dict__ or slots directly (native classes have neither), and a
# Final tuple unpacked at import (mypyc leaves the Final unset).
"$py" - <<'PY'
import re
p = "groundstation/catenary.py"
s = open(p).read()
a = s.index("_SET_A = Catenary")
b = s.index("\n\n\n", s.index("def _make_catenary"))
s = (s[:a] + "def _make_catenary(a: Any, x0: Any, c: Any, x1: Any, y1: Any, u1: Any) -> Catenary:\n"
     "    return Catenary(a, x0, c, x1, y1, u1)" + s[b:])
s = s.replace("_T_OF_W: Final = ", "_T_OF_W = ")
open(p, "w").write(s)
p = "groundstation/localization.py"
s = open(p).read()
s = s.replace('    obj: PositionEstimate = _new_object(PositionEstimate)\n'
              '    _set_attr(obj, "__dict__", fields)\n    return obj',
              '    return PositionEstimate(**fields)  # type: ignore[arg-type]')
open(p, "w").write(s)
PY
t0=$(date +%s)
"$repo/.venv/bin/mypyc" groundstation/catenary.py groundstation/localization.py \
    > "$work/build.log" 2>&1 || { tail -30 "$work/build.log"; exit 1; }
ls groundstation/localization.*.so groundstation/catenary.*.so > /dev/null
echo "compiled 2 modules in $(( $(date +%s) - t0 )) s"
for _ in 1 2 3; do
    for tree in src plain; do
        echo "== $tree"
        (cd "$work/$tree" && PYTHONPATH="$work/$tree" "$py" -m benchmarks.bench_pipeline --quick \
            | grep -E '^\| (localize|filter|sum of stages|\*\*Pipeline.handle)')
    done
done
