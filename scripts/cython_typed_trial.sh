#!/usr/bin/env bash
# What a compiled second implementation of one stage buys. The arithmetic of the
# localization's fast path (localization._localize_tension_free: the drone's and six sigma
# points' closed-form catenary positions, the unscented transform) written in typed Cython
# (C doubles, in the Python's order of operations), compiled, and timed against the Python
# on the same 2,000 converged hover inputs: the arithmetic alone (a tuple out) and with the
# same PositionEstimate built from it (what the rest of the estimator reads).
# Needs gcc, the Python headers and PyPI (Cython and setuptools go into a throw-away venv).
#   scripts/cython_typed_trial.sh      # ~15 s (the venv and the compile)
# Results: docs/service_profile.md, section 7.
set -euo pipefail
repo=$(cd "$(dirname "$0")/.." && pwd)
py="$repo/.venv/bin/python"
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
"$py" -m venv "$work/cy"
"$work/cy/bin/pip" install -q --disable-pip-version-check cython setuptools
cat > "$work/kernel.pyx" <<'PYX'
# cython: language_level=3, boundscheck=False, wraparound=False, cdivision=True
# The arithmetic of groundstation.localization._localize_tension_free, typed (C doubles),
# in its order of operations: what a compiled second implementation of one stage buys.
from libc.math cimport sqrt, hypot, asinh, atan2, sin, cos, isfinite, INFINITY

cdef double MIN_HORIZONTAL_N = 1e-9
cdef double SIGMA_SCALE = 1.7320508075688772  # sqrt(3)
cdef double SIGMA_WEIGHT = 1.0 / 6.0

def free(double tx, double ty, double tz, double cxx, double cxy, double cxz,
         double cyy, double cyz, double czz, double omega, double big_l,
         double bx, double by, double bz, double floor_z_m, double plumb_k):
    cdef double horizontal_n = hypot(tx, ty)
    if not horizontal_n > MIN_HORIZONTAL_N:
        return None
    cdef double ux_t = -tx / horizontal_n, uy_t = -ty / horizontal_n
    cdef double var_side = uy_t * uy_t * cxx - 2.0 * ux_t * uy_t * cxy + ux_t * ux_t * cyy
    cdef double std_t = sqrt(0.0 if var_side < 0.0 else var_side) / horizontal_n
    if not (0.0 < std_t <= 0.5 / plumb_k):
        return None
    cdef double beta = atan2(uy_t + 0.0, ux_t) + 0.0 / 1.0
    beta = atan2(sin(beta), cos(beta))
    cdef double ux = cos(beta), uy = sin(beta)
    if not cxx > 0.0:
        return None
    cdef double l00 = sqrt(cxx), l10 = cxy / l00, l20 = cxz / l00
    cdef double d1 = cyy - l10 * l10
    if not d1 > 0.0:
        return None
    cdef double l11 = sqrt(d1), l21 = (cyz - l20 * l10) / l11
    cdef double d2 = czz - l20 * l20 - l21 * l21
    if not d2 > 0.0:
        return None
    if not (cxx < 1e150 and cyy < 1e150):
        return None
    cdef double k = SIGMA_SCALE
    cdef double a0 = k * l00, b0 = k * l10, b1 = k * l11, c0 = k * l20, c1 = k * l21, c2 = k * sqrt(d2)
    cdef double nx = -tx, ny = -ty, nz = -tz
    cdef double px[6]
    cdef double py[6]
    cdef double pz[6]
    px[0] = nx - a0; py[0] = ny - b0; pz[0] = nz - c0
    px[1] = nx - 0.0; py[1] = ny - b1; pz[1] = nz - c1
    px[2] = nx - 0.0; py[2] = ny - 0.0; pz[2] = nz - c2
    px[3] = nx + a0; py[3] = ny + b0; pz[3] = nz + c0
    px[4] = nx + 0.0; py[4] = ny + b1; pz[4] = nz + c1
    px[5] = nx + 0.0; py[5] = ny + 0.0; pz[5] = nz + c2
    cdef bint has_floor = floor_z_m != -INFINITY
    cdef double limit = floor_z_m + 1e-6
    cdef double a = horizontal_n / omega, s2 = -tz / omega, t = big_l - s2
    cdef double hyp_s = hypot(a, s2)
    cdef double r_0 = a * asinh(s2 / a) + a * asinh(t / a) if a > 0.0 else 0.0
    cdef double z0 = bz + (2.0 * s2 - big_l) * big_l / (hyp_s + hypot(a, t))
    if has_floor and not ((z0 if s2 < 0.0 else (bz if s2 > big_l else z0 - (hyp_s - a))) > limit):
        return None
    cdef double r0 = r_0 if not r_0 < 0.0 else 0.0
    cdef double var_r = 0.0, var_z = 0.0, dxx = 0.0, dxy = 0.0, dyy = 0.0, dxz = 0.0, dyz = 0.0
    cdef double hx0 = r0 * ux, hy0 = r0 * uy
    cdef double xi, yi, vi, hi, ri, zi, dr, dz, dx, dy
    cdef int i
    for i in range(6):
        xi = px[i]; yi = py[i]; vi = pz[i]
        hi = hypot(xi, yi)
        a = hi / omega
        s2 = vi / omega
        t = big_l - s2
        hyp_s = hypot(a, s2)
        ri = a * asinh(s2 / a) + a * asinh(t / a) if a > 0.0 else 0.0
        zi = bz + (2.0 * s2 - big_l) * big_l / (hyp_s + hypot(a, t))
        if has_floor and not ((zi if s2 < 0.0 else (bz if s2 > big_l else zi - (hyp_s - a))) > limit):
            return None
        dr = ri - r0
        dz = zi - z0
        var_r += dr * dr
        var_z += dz * dz
        if hi > 0.0:
            dx = ri * (xi / hi) - hx0
            dy = ri * (yi / hi) - hy0
        else:
            dx = ri * ux - hx0
            dy = ri * uy - hy0
        dxx += dx * dx; dxy += dx * dy; dyy += dy * dy; dxz += dx * dz; dyz += dy * dz
    cdef double w = SIGMA_WEIGHT
    var_z = w * var_z
    cdef double sxx = w * dxx, sxy = w * dxy, syy = w * dyy, sxz = w * dxz, syz = w * dyz
    values = (bx + r0 * ux, by + r0 * uy, z0, sqrt(sxx), sqrt(syy), sqrt(var_z),
              sxx, sxy, sxz, sxy, syy, syz, sxz, syz, var_z)
    if not (isfinite(sum(values)) and isfinite(r_0 + w * var_r)):
        return None
    return values, r0, r_0, beta, std_t
PYX
cat > "$work/setup.py" <<'PY'
from Cython.Build import cythonize
from setuptools import Extension, setup
setup(ext_modules=cythonize([Extension("kernel", ["kernel.pyx"], extra_compile_args=["-O2"])],
                            quiet=True), script_args=["build_ext", "--inplace"])
PY
(cd "$work" && "$work/cy/bin/python" setup.py > build.log 2>&1) || { tail -30 "$work/build.log"; exit 1; }
cat > "$work/time_kernel.py" <<'PY'
"""The localization fast path in Python against its arithmetic in typed Cython, same inputs."""
import math, sys, time
import numpy as np
sys.path.insert(0, sys.argv[1])  # the compiled kernel
import kernel
from groundstation import localization as L
from groundstation.pipeline import Pipeline
from tests.test_work_budget import REGIMES, WARMUP
from tests.test_perf_equivalence import pinned_settings
# Inputs: the filter's converged estimates of the budget's hover, as the pipeline passes them.
captured = []
orig = L._localize_tension_free
def spy(*args):
    captured.append(args)
    return orig(*args)
L._localize_tension_free = spy
reg = REGIMES["hover"]
rng = np.random.default_rng(3)
pipe = Pipeline(pinned_settings())
for k in range(WARMUP + 2000):
    pipe.handle(reg["make"](k, rng), k * 0.004)
L._localize_tension_free = orig
cases = captured[-2000:]
# Same answers?
worst = 0.0
for args in cases:
    p = orig(*args)
    c = kernel.free(*args)
    assert (p is None) == (c is None)
    if p is None:
        continue
    vals, r0, r_0, beta, std_t = c
    py_vals = [*p.position_world_m.tolist(), *p.std_world_m.tolist(), *p.cov_world_m2.ravel().tolist()]
    for a, b in zip(py_vals, vals):
        worst = max(worst, abs(a - b) / max(abs(a), 1e-300))
def best_us(fn, reps=7):
    best = math.inf
    for _ in range(reps):
        t0 = time.perf_counter_ns()
        for args in cases:
            fn(*args)
        best = min(best, (time.perf_counter_ns() - t0) / len(cases) / 1e3)
    return best
def kernel_then_objects(*args):
    out = kernel.free(*args)
    vals, r0, r_0, beta, std_t = out
    pos, std, cov = L._frozen_arrays(*vals)
    return L._estimate({"position_world_m": pos, "std_world_m": std, "cov_world_m2": cov,
        "radial_m": r0, "radial_interval_m": (r_0, r_0), "azimuth_rad": beta,
        "azimuth_determined": True, "floor_contact": False, "floor_run_m": 0.0, "case": "free",
        "azimuth_std_rad": std_t, "azimuth_source": "tension", "elevation_used": False})
print(f"{len(cases)} converged hover cases; largest relative difference {worst:.1e}")
for _ in range(2):
    print(f"Python  _localize_tension_free            {best_us(orig):6.2f} us")
    print(f"Cython  the arithmetic (typed), a tuple out  {best_us(kernel.free):6.2f} us")
    print(f"Cython  the arithmetic + the same PositionEstimate {best_us(kernel_then_objects):6.2f} us")
PY
cd "$repo" && PYTHONPATH="$repo" "$py" "$work/time_kernel.py" "$work"
