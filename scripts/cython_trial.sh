#!/usr/bin/env bash
# A trial of a compiled estimator without a second implementation: Cython compiles
# the estimator's modules as they are (pure Python mode, no type declarations added), and
# Pipeline.handle is timed on a converged hover, compiled and not, alternately, in one run.
# Needs gcc, the Python headers and PyPI (Cython and setuptools go into a throw-away venv).
#   scripts/cython_trial.sh            # ~5 min on 2 cores, most of it the compile
# Results: docs/service_profile.md, section 7.
set -euo pipefail
repo=$(cd "$(dirname "$0")/.." && pwd)
py="$repo/.venv/bin/python"
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
git clone -q "$repo" "$work/src"
cd "$work/src"
python3 -m venv "$work/cy"
"$work/cy/bin/pip" install -q --disable-pip-version-check cython setuptools
# Cython 3.3.1 crashes on a nested unpacking in an assignment (localization.py,
# `a, s2, (paa, pas, pss) = fused`): the same statement in two lines for the trial.
sed -i 's/^    a, s2, (paa, pas, pss) = fused$/    a, s2, _p = fused\n    paa, pas, pss = _p/' \
    groundstation/localization.py
# Every module of the per-message path but messages.py and pipeline.py (compiled, their
# pydantic models no longer build: pydantic reads a compiled method as a field).
mods=(localization tension slow_accel tension_change tension_noise tension_drift
      tension_kalman contact calibration catenary frozen
      estimator/drone estimator/observation estimator/filter_control estimator/output
      estimator/gate estimator/contact_control estimator/localize_control
      estimator/follow_control estimator/checks)
list=$(printf 'groundstation/%s.py,' "${mods[@]}")
cat > "$work/setup_trial.py" <<'EOF'
import sys
from Cython.Build import cythonize
from setuptools import setup
mods = sys.argv.pop(1).rstrip(",").split(",")
setup(ext_modules=cythonize(mods, compiler_directives={"language_level": 3}, quiet=True),
      script_args=["build_ext", "--inplace"])
EOF
cat > "$work/time_handle.py" <<'EOF'
import gc, sys, time
from benchmarks.bench_service import _telemetry_payloads
from groundstation import localization
from groundstation.bus import Sample
from groundstation.evaluation import settings_for
from groundstation.pipeline import Pipeline
payloads = [r[0] for r in _telemetry_payloads(1, 4500 / 250.0, 0)]
best = float("inf")
for _ in range(3):
    pipe = Pipeline(settings_for())
    for p in payloads[:500]:
        pipe.handle(Sample("tether/d0/telemetry", p), 0.0)
    samples = [Sample("tether/d0/telemetry", p) for p in payloads[500:]]
    gc.disable()
    t0 = time.process_time()
    for s in samples:
        pipe.handle(s, 0.0)
    best = min(best, (time.process_time() - t0) / len(samples) * 1e6)
    gc.enable()
kind = "compiled" if localization.__file__.endswith(".so") else "Python"
print(f"{kind:8s} Pipeline.handle {best:6.1f} us CPU per message (best of 3)")
EOF
t0=$(date +%s)
"$work/cy/bin/python" "$work/setup_trial.py" "$list" > "$work/build.log" 2>&1 \
    || { tail -30 "$work/build.log"; exit 1; }
echo "compiled ${#mods[@]} modules in $(( $(date +%s) - t0 )) s"
git clone -q "$repo" "$work/plain"  # the same code, not compiled
for _ in 1 2 3; do
    (cd "$work/src" && PYTHONPATH="$work/src" "$py" "$work/time_handle.py")
    (cd "$work/plain" && PYTHONPATH="$work/plain" "$py" "$work/time_handle.py")
done
