"""Forward-backward (Rauch-Tung-Striebel) smoothing of the tension filter, for post-flight use.

Pure physics: numpy and filterpy only. The causal filter (:class:`groundstation.tension.
TensionFilter`) estimates the tension at sample k from the samples up to k; after the flight
every sample's estimate can also use the samples after it. For the filter's model
(``eq:Kalman_vars``: A = C = I, a random walk observed in noise) the RTS smoother does that
exactly: a forward Kalman pass, then backwards::

    P-_k+1 = P_k + Q_k+1                 (the prediction the forward pass made)
    G_k    = P_k (P-_k+1)^-1             (smoother gain)
    xs_k   = x_k + G_k (xs_k+1 - x_k)
    Ps_k   = P_k + G_k (Ps_k+1 - P-_k+1) G_k'

While the drone hovers the causal filter's state is (T, v) per axis, the velocity beside the
tension with the thrust balance as its input and ``v = 0`` observed
(:class:`groundstation.tension_kalman.HoverVelocity`); the smoother runs that model too (six
states; :func:`_smooth_segment`), so a hover's thrust balance informs the smoothed tension as
it does the causal one (without it the smoothed dwell was worse than the causal estimate:
docs/smoother.md).

Here filterpy is the right tool (``KalmanFilter.batch_filter`` then ``rts_smoother``, whole
arrays, offline): it runs on the causal filter's own trace (:class:`groundstation.tension.
FilterStep`), i.e. the observations z, the noise R it had learnt, the process noise Q it
chose at each step (hover, drift adaptation, coasts) and the hover's part
(:class:`groundstation.tension.HoverStep`). Not in the trace: the rescaling of P when the
learnt R moves by more than 1 % (the smoother's forward pass keeps the unscaled P).

Where the causal filter found a change (a tug), the regime it restarted from began ``restart``
updates earlier: the smoother cuts there, so it never averages across a tug, and each regime is
smoothed from an uninformative start (x = z, P = R). A reset (ground, silence) cuts too.
docs/smoother.md measures the gain.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal

import numpy as np
from filterpy.kalman import KalmanFilter
from numpy.typing import NDArray

from groundstation.localization import localize_batch
from groundstation.tension import FilterStep

__all__ = ["Segment", "SmoothedTension", "localize_smoothed", "segments", "smooth_tension"]

FloatArray = NDArray[np.float64]
_EYE3 = np.eye(3)
_EYE3.setflags(write=False)


@dataclass(frozen=True, slots=True)
class Segment:
    """One regime of a trace: ``trace[start:stop]``, smoothed on its own.

    ``begin``: how the regime's first step starts the forward pass: ``"state"`` (a
    ``"start"`` step: its x and P), ``"diffuse"`` (an init, or the first update of a regime
    found by a change: x = z, P = R), ``"prior"`` (the first update after a reset with a
    prior: that prior, then the update).
    """

    start: int
    stop: int
    begin: Literal["state", "diffuse", "prior"]
    prior: tuple[tuple[float, float, float], tuple[float, float, float]] | None = None


@dataclass(frozen=True, slots=True)
class SmoothedTension:
    """The smoothed tension at every step of a trace (NaN at resets)."""

    tension_world_n: FloatArray
    """Smoothed tension, world, N, shape (n, 3)."""
    variance_n2: FloatArray
    """Diagonal of its covariance, N^2, shape (n, 3)."""
    segments: tuple[Segment, ...]
    """The regimes, smoothed each on its own."""


def segments(trace: Sequence[FilterStep]) -> list[Segment]:
    """Splits a trace into regimes: at resets, and where each detected change began.

    Args:
        trace: The causal filter's steps (:attr:`TensionFilter.trace`).

    Returns:
        The regimes in order; steps outside every regime are resets (and anything before the
        first state, which has nothing to start from).
    """
    out: list[Segment] = []
    start: int | None = None
    begin: Literal["state", "diffuse", "prior"] = "diffuse"
    prior: tuple[tuple[float, float, float], tuple[float, float, float]] | None = None
    pending_prior: tuple[tuple[float, float, float], tuple[float, float, float]] | None = None
    updates: list[int] = []  # the update steps of the open regime

    def close(stop: int) -> None:
        if start is not None and stop > start:
            out.append(Segment(start, stop, begin, prior))

    for i, step in enumerate(trace):
        if step.kind == "reset":
            close(i)
            start, updates = None, []
            pending_prior = None
            if step.x_n is not None and step.p_n2 is not None:
                pending_prior = (step.x_n, step.p_n2)
        elif step.kind in ("start", "init") or start is None:
            if step.kind == "coast":
                continue  # nothing to start from
            close(i)
            start, updates = i, []
            begin = "state" if step.kind == "start" else "diffuse"
            prior = None
            if step.kind == "update" and pending_prior is not None:
                begin, prior = "prior", pending_prior
            pending_prior = None
        if step.kind in ("init", "update"):
            updates.append(i)
        if step.kind == "update" and step.restart > 0 and start is not None:
            n = step.restart
            # (a regime that began before this segment: from its first update, which is not
            # the segment's first step where that is a merged state, kind "start")
            cut = updates[-n] if n <= len(updates) else (updates[0] if updates else start)
            if cut > start:
                close(cut)
                start, begin, prior = cut, "diffuse", None
            elif begin != "diffuse":
                begin, prior = "diffuse", None  # the whole regime is the new one
            updates = updates[-n:]
    close(len(trace))
    return out


def smooth_tension(trace: Sequence[FilterStep]) -> SmoothedTension:
    """RTS-smoothed tension at every step of the causal filter's trace.

    Args:
        trace: The causal filter's steps (:attr:`TensionFilter.trace`).

    Returns:
        The smoothed tension and its variance per step, NaN where a step belongs to no
        regime (resets).
    """
    n = len(trace)
    x_out = np.full((n, 3), math.nan)
    p_out = np.full((n, 3), math.nan)
    segs = segments(trace)
    for seg in segs:
        xs, ps = _smooth_segment(trace[seg.start : seg.stop], seg)
        x_out[seg.start : seg.stop] = xs
        p_out[seg.start : seg.stop] = ps
    for a in (x_out, p_out):
        a.setflags(write=False)
    return SmoothedTension(x_out, p_out, tuple(segs))


_IDLE_VAR_M2PS2 = 1.0
"""The velocity's variance where the filter does not follow it (no hover), (m/s)^2: any
positive value; nothing observes the velocity there and the tension does not depend on it."""


def _smooth_segment(steps: Sequence[FilterStep], seg: Segment) -> tuple[FloatArray, FloatArray]:
    """Forward pass (filterpy) and RTS backward pass over one regime; (x, diag P) per step.

    The state per world axis is (T, v), the causal filter's while it hovers
    (:class:`~groundstation.tension_kalman.HoverVelocity`, from each step's
    :class:`~groundstation.tension.HoverStep`): ``v = v_prev + d·(T_prev − h)`` (a hover
    that begins: ``v = d·(T_prev − h)``, its noise σ_v² larger), ``0 = v`` observed beside
    the tension. Outside a hover v is unobserved noise (F = 0 for it, variance
    ``_IDLE_VAR_M2PS2``), so T is smoothed as before. The known input ``−d·h`` is the forward
    pass's ``B·u``; filterpy's ``rts_smoother`` has no input, so the backward pass runs on
    ``x − c``, c the input's own response (``c = F c_prev + B u``, c = 0 at the start), which
    obeys the same model without it, and c is added back.
    """
    first = steps[0]
    kf = KalmanFilter(dim_x=6, dim_z=6)
    kf.x = np.zeros((6, 1))
    kf.P = np.zeros((6, 6))
    v_var = _IDLE_VAR_M2PS2 if first.hover is None else first.hover.start_var_m2ps2
    kf.P[3:, 3:] = _EYE3 * v_var  # v = 0, uncorrelated (a hover begins)
    if seg.begin == "state":
        assert first.x_n is not None and first.p_n2 is not None
        kf.x[:3, 0] = first.x_n
        kf.P[:3, :3] = np.diag(first.p_n2)
    elif seg.begin == "prior":
        assert seg.prior is not None and first.z_n is not None and first.r_n2 is not None
        kf.x[:3, 0] = seg.prior[0]  # x- = the prior
        kf.P[:3, :3] = np.diag(seg.prior[1])
        # no time has passed since the prior: no prediction, the update alone
        kf.update(
            np.array([*first.z_n, 0.0, 0.0, 0.0]).reshape(6, 1),
            R=_block(np.diag(first.r_n2), _EYE3 * _IDLE_VAR_M2PS2),
            H=_H_TENSION,
        )
    else:
        assert first.z_n is not None and first.r_n2 is not None
        kf.x[:3, 0] = first.z_n  # an uninformative prior updated once:
        kf.P[:3, :3] = np.diag(first.r_n2)  # x = z, P = R
    m = len(steps)
    Xs = np.empty((m, 6, 1))
    Ps = np.empty((m, 6, 6))
    Xs[0], Ps[0] = kf.x, kf.P
    Fs = [_F_IDLE] * m
    Qs = np.zeros((m, 6, 6))
    us = np.zeros((m, 6, 1))
    if m > 1:
        rest = steps[1:]
        zs: list[FloatArray | None] = []
        Rs, Hs = [], []
        for j, s in enumerate(rest, start=1):
            Qs[j, :3, :3] = np.diag(s.q_n2)
            hov = s.hover
            if hov is None:
                Qs[j, 3:, 3:] = _EYE3 * _IDLE_VAR_M2PS2
                Hs.append(_H_TENSION)
                r_v = _EYE3 * _IDLE_VAR_M2PS2
            else:
                d = hov.gain_s_per_kg
                Fs[j] = _f_start(d) if hov.started else _f_hover(d)
                qv = hov.velocity_noise_m2ps2 + (hov.start_var_m2ps2 if hov.started else 0.0)
                Qs[j, 3:, 3:] = _EYE3 * qv
                us[j, 3:, 0] = [-d * hov.hover_model_n[0], -d * hov.hover_model_n[1],
                                -d * hov.hover_model_n[2]]  # fmt: skip
                Hs.append(_EYE6)
                r_v = _EYE3 * hov.rest_var_m2ps2
            # Column vectors: filterpy's update reshapes z only when it is not given H.
            zs.append(None if s.z_n is None else np.array([*s.z_n, 0.0, 0.0, 0.0]).reshape(6, 1))
            Rs.append(_block(_EYE3 if s.r_n2 is None else np.diag(s.r_n2), r_v))
        # x- = F x + B u, P- = F P F' + Q; then the update with z = (z_T, 0) (coasts: none)
        means, covs, _, _ = kf.batch_filter(
            zs, Fs=Fs[1:], Qs=list(Qs[1:]), Hs=Hs, Rs=Rs, Bs=[_EYE6] * (m - 1), us=list(us[1:])
        )
        Xs[1:], Ps[1:] = means, covs
        c = np.zeros((m, 6, 1))  # the input's response: the smoother runs on x - c
        for j in range(1, m):
            c[j] = Fs[j] @ c[j - 1] + us[j]
        # G_k = P_k F' (F P_k F' + Q_k+1)^-1, xs_k = x_k + G_k (xs_k+1 - F x_k), Ps likewise
        Ys, Ps, _, _ = kf.rts_smoother(Xs - c, Ps, Fs=Fs, Qs=list(Qs))
        Xs = Ys + c
    return Xs[:, :3, 0], np.diagonal(Ps[:, :3, :3], axis1=1, axis2=2)


def _block(a: FloatArray, b: FloatArray) -> FloatArray:
    """The block-diagonal matrix diag(a, b) of two 3x3 blocks."""
    out = np.zeros((6, 6))
    out[:3, :3] = a
    out[3:, 3:] = b
    return out


def _f_hover(d: float) -> FloatArray:
    """The transition while hovering: T = T_prev, v = v_prev + d·T_prev (+ input)."""
    f = _EYE6.copy()
    f[3:, :3] = _EYE3 * d
    return f


def _f_start(d: float) -> FloatArray:
    """The transition where a hover begins: v = d·T_prev (+ input) from v = 0."""
    f = _f_hover(d)
    f[3:, 3:] = 0.0
    return f


_EYE6 = np.eye(6)
_EYE6.setflags(write=False)
_F_IDLE = _block(_EYE3, np.zeros((3, 3)))
"""The transition outside a hover: T = T_prev, v forgotten (noise of ``_IDLE_VAR_M2PS2``)."""
_F_IDLE.setflags(write=False)
_H_TENSION = _block(_EYE3, np.zeros((3, 3)))
"""The observation outside a hover: the tension alone (the velocity's rows zero)."""
_H_TENSION.setflags(write=False)


def localize_smoothed(
    tension_world_n: FloatArray,
    variance_n2: FloatArray,
    weight_n_per_m: FloatArray,
    length_m: FloatArray,
    base_world_m: FloatArray,
    floor_z_m: FloatArray,
    model_var_n2: FloatArray | None = None,
) -> tuple[FloatArray, FloatArray]:
    """Catenary positions of the smoothed tensions (azimuth from the tension itself).

    Args:
        tension_world_n: Smoothed tension, world, N, shape (n, 3).
        variance_n2: Its variance per axis, N^2, shape (n, 3).
        weight_n_per_m: Tether weight per metre, N/m, shape (n,).
        length_m: Tether length, m, shape (n,).
        base_world_m: Base exit, world, m, shape (n, 3).
        floor_z_m: Floor height, m, shape (n,).
        model_var_n2: The calibration's misfit per world axis, N², shape (n, 3) or None
            (``localization.try_localize``: it widens the position's covariance).

    Returns:
        Position (world, m) and its standard deviation (m), each shape (n, 3), NaN where
        the catenary has no solution or the tension is NaN.
    """
    n = len(tension_world_n)
    pos = np.full((n, 3), math.nan)
    std = np.full((n, 3), math.nan)
    ok = np.all(np.isfinite(tension_world_n), axis=1) & np.all(np.isfinite(variance_n2), axis=1)
    idx = np.nonzero(ok)[0]
    if len(idx):
        covs = np.zeros((len(idx), 3, 3))
        for a in range(3):
            covs[:, a, a] = variance_n2[idx, a]
        found = localize_batch(
            tension_world_n[idx],
            covs,
            weight_n_per_m[idx],
            length_m[idx],
            base_world_m[idx],
            floor_z_m[idx],
            model_var_n2=None if model_var_n2 is None else model_var_n2[idx],
        )
        for i, p in zip(idx, found, strict=True):
            if p is not None:
                pos[i] = p.position_world_m
                std[i] = p.std_world_m
    return pos, std
