"""The bridge's logic, without threads or I/O: which variables, which blocks, units, alignment,
thrust, and the command gate (watchdog and stop latch).

The runner (:mod:`groundstation.bridges.crazyflie.runner`) feeds these with what the link
and the bus deliver and with the host's monotonic clock as a parameter (``now_s``).

Units at the Crazyflie side (firmware log variables):

=========================  ===========  =========================================
variable                   unit         Telemetry field
=========================  ===========  =========================================
``acc.x/y/z``              g            ``accel_mps2`` (× 9.81), body frame
``gyro.x/y/z``             deg/s        ``gyro_rps`` (× π/180), body frame
``stateEstimate.qw..qz``   –            ``quat_wxyz`` (body → world, normalised)
``motor.m1..m4``           0..65535     ``thrust_n`` via ``thrust_map``, summed
``pwm.m1_pwm..m4_pwm``     0..65535     (the same; firmware of about 2021–2022 only)
``pm.vbat``                V            ``vbat_v``
``supervisor.info``        bit field    ``armed`` (bit 1, "is armed")
``stateEstimate.x/y/z``    m            ``position_m`` (``onboard_position``)
``kalman.varX/Y/Z``        m²           ``position_std_m`` (square root)
``kalman.varPX/PY/PZ``     m²/s²        (whether the estimator has settled)
=========================  ===========  =========================================

``kalman.varX/Y/Z`` are the Kalman estimator's position variances and ``kalman.varPX/PY/PZ``
its (body-frame) velocity variances (estimator_kalman.c); cflib's ``reset_estimator`` waits on
the latter, and so does :class:`SettleWatch`.

Which battery compensation the motor variable carries decides ``[calibration]
thrust_vbat_slope_per_v`` (docs/real-lab.md, "compensating once"). Current firmware logs
``motor.m1..m4`` *after* the battery compensation (the stabilizer runs batteryCompensation,
then powerDistributionCap, then setMotorRatios, and ``motor.m*`` is the ratio written to the
motor timers) and has no ``pwm`` group: fit the slope. Firmware of about 2021–2022 logged
``motor.m1..m4`` as the power distribution's request *before* the compensation that
``motorsSetRatio`` applied (keep the slope 0) and ``pwm.m1_pwm..m4_pwm`` as the duty after it
(fit the slope).

The Crazyflie's body frame is the contract's (x forward, y left, z up) and its accelerometer
reads about +1 g on z level at rest, so no axis changes sign.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Literal

from groundstation.bridges.crazyflie.link import TYPE_SIZES, LogBlock
from groundstation.config import CrazyflieSection
from groundstation.messages import Telemetry

__all__ = [
    "ACC",
    "ATTITUDE",
    "GYRO",
    "G_MPS2",
    "MAX_BLOCK_BYTES",
    "NOT_LOGGED_CONSEQUENCE",
    "POSITION",
    "POSITION_VAR",
    "VELOCITY_VAR",
    "VMOTOR2THRUST",
    "Aligned",
    "Aligner",
    "CommandGate",
    "MissingVariables",
    "MocapPose",
    "OnboardPosition",
    "Phase",
    "Reach",
    "SetpointCommand",
    "SettleWatch",
    "Skip",
    "VariablePlan",
    "build_telemetry",
    "plan_blocks",
    "plan_variables",
    "thrust_cubic_n",
    "thrust_n",
    "yaw_deg_from_quat",
]

G_MPS2 = 9.81
"""m/s² per g for ``acc.*`` (the value the contract's at-rest reading uses)."""
MAX_BLOCK_BYTES = 26
"""Log data per CRTP packet (cflib ``LogConfig.MAX_LEN``: 30 bytes less id and timestamp)."""
TIMESTAMP_WRAP_MS = 1 << 24
"""Log timestamps are 24-bit milliseconds (they wrap after 4.66 h)."""

ACC = ("acc.x", "acc.y", "acc.z")
GYRO = ("gyro.x", "gyro.y", "gyro.z")
ATTITUDE = ("stateEstimate.qw", "stateEstimate.qx", "stateEstimate.qy", "stateEstimate.qz")
MOTORS = {
    "motor": ("motor.m1", "motor.m2", "motor.m3", "motor.m4"),
    "pwm": ("pwm.m1_pwm", "pwm.m2_pwm", "pwm.m3_pwm", "pwm.m4_pwm"),
}
POSITION = ("stateEstimate.x", "stateEstimate.y", "stateEstimate.z")
"""The onboard estimator's position, world frame, m (``stateEstimateZ.*`` holds the same in mm as
int16: 6 bytes instead of 12, but the block needs a packet of its own either way)."""
POSITION_VAR = ("kalman.varX", "kalman.varY", "kalman.varZ")
"""The Kalman estimator's position variances, m²."""
VELOCITY_VAR = ("kalman.varPX", "kalman.varPY", "kalman.varPZ")
"""The Kalman estimator's velocity variances, m²/s²: what cflib's ``reset_estimator`` watches."""
VBAT = "pm.vbat"
SUPERVISOR_INFO = "supervisor.info"
SUPERVISOR_IS_ARMED_BIT = 1
"""cflib ``supervisor.BIT_IS_ARMED``; the firmware's ``supervisor.info`` documents the same."""


NOT_LOGGED_CONSEQUENCE: Mapping[str, str] = {
    VBAT: "Telemetry carries no vbat_v, so the service applies no battery term "
    "([calibration] thrust_vbat_slope_per_v is ignored)",
    SUPERVISOR_INFO: "Telemetry says armed: true (the contract's default) whatever the motors "
    "do, so the service tells the floor from thrust and motion only",
}
"""What the service loses when the firmware does not log an optional variable."""


class MissingVariables(ValueError):
    """The firmware's log TOC lacks variables the configuration needs (all named)."""

    def __init__(self, missing: Sequence[str], uri: str, hint: str = "") -> None:
        self.missing = tuple(missing)
        super().__init__(
            f"{uri}: the firmware does not log {', '.join(self.missing)} "
            + (
                f"({hint})"
                if hint
                else "(check [crazyflie] motor_variables / attitude_source / armed_source, or "
                "the firmware version)"
            )
        )


@dataclass(frozen=True, slots=True)
class VariablePlan:
    """Which variables to log, split into blocks."""

    fast: tuple[LogBlock, ...]
    """Sampled every telemetry period and aligned by timestamp."""
    slow: tuple[LogBlock, ...]
    """Battery and armed state: the latest value joins each Telemetry."""
    motors: tuple[str, ...]
    attitude: tuple[str, ...]
    """``stateEstimate.q*`` or empty when the attitude comes from motion capture."""
    armed: bool
    """``supervisor.info`` is logged."""
    vbat: bool
    not_logged: tuple[str, ...] = ()
    """Optional variables the firmware lacks (``pm.vbat``, ``supervisor.info`` with
    ``armed_source = "auto"``); :data:`NOT_LOGGED_CONSEQUENCE` says what that costs."""
    position: bool = False
    """``stateEstimate.x/y/z`` and ``kalman.varX/Y/Z`` are logged (a fast block of their own)."""
    settle: bool = False
    """``kalman.varPX/PY/PZ`` are logged (slow block): take-off waits for them to settle."""


def plan_blocks(
    name: str,
    groups: Sequence[Sequence[str]],
    toc: Mapping[str, str],
    period_ms: int,
    fetch_as: Mapping[str, str] | None = None,
    max_bytes: int = MAX_BLOCK_BYTES,
) -> list[LogBlock]:
    """Pack groups of variables, in order, into blocks of at most ``max_bytes`` of data.

    A group (the components of one vector) stays in one block; a group larger than a packet
    is split. Each group goes into the first block with room (first fit), so a small group
    may fill a gap left earlier.

    Args:
        name: prefix of the block names (``name0``, ``name1``, ...).
        groups: ``group.name`` variables, e.g. ``[ACC, GYRO, ATTITUDE]``.
        toc: the firmware's log TOC, ``{"group.name": C type}``.
        period_ms: period of every block, a multiple of 10 ms in 10..2540.
        fetch_as: a narrower type to fetch some variables as (default: the stored type).

    Raises:
        ValueError: a period not in 10 ms steps.
    """
    if period_ms % 10 or not 10 <= period_ms <= 2540:
        raise ValueError(f"log period {period_ms} ms is not a multiple of 10 ms in 10..2540")
    fetch_as = fetch_as or {}
    blocks: list[list[tuple[str, str]]] = []
    used: list[int] = []

    def place(items: list[tuple[str, str]], size: int) -> None:
        for i, u in enumerate(used):
            if u + size <= max_bytes:
                blocks[i].extend(items)
                used[i] += size
                return
        blocks.append(list(items))
        used.append(size)

    for group in groups:
        items = [(v, fetch_as.get(v, toc[v])) for v in group]
        size = sum(TYPE_SIZES[t] for _, t in items)
        if size <= max_bytes:
            place(items, size)
        else:
            for item in items:
                place([item], TYPE_SIZES[item[1]])
    return [
        LogBlock(f"{name}{i}", period_ms, tuple(v for v, _ in b), tuple(t for _, t in b))
        for i, b in enumerate(blocks)
    ]


def plan_variables(section: CrazyflieSection, toc: Mapping[str, str], uri: str) -> VariablePlan:
    """Check the configuration's variables against the TOC and lay out the log blocks.

    Raises:
        MissingVariables: naming every variable the configuration needs and the TOC lacks.
    """
    motors = MOTORS[section.motor_variables]
    attitude = ATTITUDE if section.attitude_source == "estimator" else ()
    needed = [*ACC, *GYRO, *attitude, *motors]
    if section.thrust_model != "pwm_map":
        needed.append(VBAT)  # the firmware's cubic is in the motor's voltage
    if section.armed_source == "supervisor":
        needed.append(SUPERVISOR_INFO)
    position = section.onboard_position != "none"
    settle = position or section.send_extpos
    if position:
        needed.extend((*POSITION, *POSITION_VAR))
    if settle:
        needed.extend(VELOCITY_VAR)
    missing = [v for v in needed if v not in toc]
    if missing:
        hint = ""
        if section.motor_variables == "pwm" and all(m in toc for m in MOTORS["motor"]):
            hint = (
                'current firmware has no pwm group: set [crazyflie] motor_variables = "motor" '
                "(there the duty after battery compensation: fit [calibration] "
                "thrust_vbat_slope_per_v; docs/real-lab.md, compensating once)"
            )
        if any(v in missing for v in (*POSITION_VAR, *VELOCITY_VAR)):
            hint = (
                "onboard_position and send_extpos need the Kalman estimator's log variables "
                "(kalman.*): a firmware built without the Kalman estimator cannot give them"
            )
        raise MissingVariables(missing, uri, hint)
    armed = section.armed_source != "none" and SUPERVISOR_INFO in toc
    vbat = VBAT in toc
    not_logged = tuple(
        v
        for v, lacking in ((VBAT, not vbat), (SUPERVISOR_INFO, section.armed_source == "auto"))
        if lacking and v not in toc
    )
    slow_vars = [v for v, on in ((VBAT, vbat), (SUPERVISOR_INFO, armed)) if on]
    if settle:
        slow_vars.extend(VELOCITY_VAR)  # 18 bytes with the battery and armed state
    # Motor commands are 0..65535 (firmware doc) but stored as uint32: fetch them as uint16
    # so that attitude and motors share one packet.
    narrow = {m: "uint16_t" for m in motors if toc[m] in ("uint32_t", "int32_t")}
    # The position and its variances (24 bytes) take a third fast packet: the first two are
    # full (24 bytes each). Sampled with the rest, they join each Telemetry by timestamp.
    onboard = (*POSITION, *POSITION_VAR) if position else ()
    groups = [g for g in (ACC, GYRO, attitude, motors, onboard) if g]
    fast = plan_blocks("tel", groups, toc, section.log_period_ms, narrow)
    slow = plan_blocks("slow", [slow_vars], toc, section.slow_period_ms) if slow_vars else []
    return VariablePlan(
        tuple(fast),
        tuple(slow),
        motors,
        attitude,
        armed,
        vbat,
        not_logged,
        position=position,
        settle=settle,
    )


def thrust_n(pwms: Sequence[float], thrust_map: Sequence[float]) -> float:
    """Collective thrust: the sum over motors of ``a·pwm² + b·pwm + c``, newtons.

    A motor at pwm 0 is off and contributes 0 (the fit's offset ``c`` would say 0.5 mN); a
    negative per-motor value is clipped to 0.
    """
    a, b, c = thrust_map
    total = 0.0
    for pwm in pwms:
        if pwm > 0:
            total += max(0.0, a * pwm * pwm + b * pwm + c)
    return total


VMOTOR2THRUST: Mapping[str, tuple[float, float, float, float]] = {
    # platform_defaults_cf2.h (CONFIG_ENABLE_THRUST_BAT_COMPENSATED), per propeller type
    "cubic_21plus": (
        -0.02476537915958403,
        0.06523793527519485,
        -0.026792504967750107,
        0.006776789303971145,
    ),
    "cubic_legacy": (
        -0.014830744918356092,
        0.04724465241828281,
        -0.01847364358025878,
        0.005960923942142,
    ),
    "cubic_upgrade_kit": (
        0.006728127583707208,
        0.01011557616217668,
        0.010263198062061085,
        0.0028358638322392503,
    ),
    # platform_defaults_cf21bl.h: the brushless Crazyflie 2.1
    "cubic_brushless": (
        -0.014058926705279723,
        0.04265273261724981,
        0.0018327760144017432,
        0.0020576974784587178,
    ),
}
"""The firmware's thrust model per propeller type (firmware 2025.09 and later):
``VMOTOR2THRUST0..3``, thrust of one motor in N as a cubic in its voltage, N/V^k."""


def thrust_cubic_n(motors: Sequence[float], vbat_v: float, coefficients: Sequence[float]) -> float:
    """Collective thrust by the firmware's own model, newtons.

    Per motor ``v = vbat · m / 65535`` (the motor's voltage) and ``f = c0 + c1·v + c2·v² +
    c3·v³`` (motors.c inverts this cubic to compensate the battery; ``motor.m*`` is the ratio
    it wrote), summed. A motor at 0 is off and contributes 0; a negative value is clipped to 0.

    Args:
        motors: ``motor.m1..m4``, 0..65535.
        vbat_v: ``pm.vbat``, V.
        coefficients: ``VMOTOR2THRUST0..3`` (:data:`VMOTOR2THRUST`).
    """
    c0, c1, c2, c3 = coefficients
    total = 0.0
    for m in motors:
        if m > 0:
            v = vbat_v * m / 65535.0
            total += max(0.0, c0 + v * (c1 + v * (c2 + v * c3)))
    return total


def yaw_deg_from_quat(quat_wxyz: Sequence[float]) -> float:
    """Yaw (rotation about world z, ZYX convention) of a body → world quaternion, degrees."""
    w, x, y, z = quat_wxyz
    return math.degrees(math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z)))


def normalise_quat(values: Sequence[float]) -> tuple[float, float, float, float] | None:
    """Unit quaternion, or None when not finite or of norm far from 1 (a broken reading)."""
    if len(values) != 4 or not all(math.isfinite(v) for v in values):
        return None
    n = math.sqrt(sum(v * v for v in values))
    if not 0.5 < n < 1.5:
        return None
    w, x, y, z = (v / n for v in values)
    return (w, x, y, z)


@dataclass(frozen=True, slots=True)
class Aligned:
    """The fast blocks of one log period, put together."""

    stamp_ms: int
    """Firmware clock of the first fast block, unwrapped, ms."""
    values: Mapping[str, float]


@dataclass
class _Unwrap:
    last_raw: int | None = None
    offset: int = 0

    def __call__(self, raw: int) -> int | None:
        """Unwrapped ms, or None when ``raw`` is not after the previous one (out of order)."""
        if self.last_raw is None:
            self.last_raw = raw
            return raw
        step = (raw - self.last_raw) % TIMESTAMP_WRAP_MS
        if step == 0 or step >= TIMESTAMP_WRAP_MS // 2:
            return None
        if raw < self.last_raw:
            self.offset += TIMESTAMP_WRAP_MS
        self.last_raw = raw
        return raw + self.offset


@dataclass
class Aligner:
    """Joins the fast blocks of one period by their firmware timestamps.

    The firmware runs a timer per block, started when the block is, so blocks of the same
    period carry timestamps offset by a fixed phase; the samples nearest the first block's
    (within half a period) are one period. A block
    sample whose timestamp is not after its block's previous one is dropped
    (``out_of_order``); a first-block sample whose partners were lost is dropped
    (``unmatched``). Counters say how many.

    Args:
        blocks: names of the fast blocks; the first one's timestamp stamps the result.
        period_ms: their common period.
    """

    blocks: Sequence[str]
    period_ms: int
    max_pending: int = 16
    out_of_order: int = 0
    unmatched: int = 0
    _pending: dict[str, deque[tuple[int, Mapping[str, float]]]] = field(default_factory=dict)
    _unwrap: dict[str, _Unwrap] = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.reset()

    def reset(self) -> None:
        """Forget everything (a new connection: the firmware clock may have restarted)."""
        self._pending = {b: deque() for b in self.blocks}
        self._unwrap = {b: _Unwrap() for b in self.blocks}

    def push(self, block: str, raw_ms: int, values: Mapping[str, float]) -> list[Aligned]:
        """Add one block sample; return the periods it completes, oldest first."""
        if block not in self._pending:
            return []
        stamp = self._unwrap[block](raw_ms)
        if stamp is None:
            self.out_of_order += 1
            return []
        queue = self._pending[block]
        queue.append((stamp, values))
        if len(queue) > self.max_pending:
            queue.popleft()
            if block == self.blocks[0]:
                self.unmatched += 1
        return self._drain()

    def _drain(self) -> list[Aligned]:
        out: list[Aligned] = []
        tol = self.period_ms / 2.0
        first = self._pending[self.blocks[0]]
        others = [self._pending[name] for name in self.blocks[1:]]
        while first:
            t0, values0 = first[0]
            for queue in others:
                while queue and queue[0][0] < t0 - tol:
                    queue.popleft()  # a period whose first-block sample was lost
                    self.unmatched += 1
            if any(q and q[0][0] > t0 + tol for q in others):
                first.popleft()  # a partner of this period was lost
                self.unmatched += 1
                continue
            if not all(others):
                break  # a partner has not arrived yet
            merged = dict(values0)
            for queue in others:
                merged.update(queue.popleft()[1])
            first.popleft()
            out.append(Aligned(t0, merged))
        return out


@dataclass(frozen=True, slots=True)
class MocapPose:
    """A motion-capture pose of the drone, world frame."""

    position_m: tuple[float, float, float]
    quat_wxyz: tuple[float, float, float, float] | None
    received_s: float
    """Host monotonic clock when it arrived, s."""


@dataclass(frozen=True, slots=True)
class OnboardPosition:
    """The onboard estimator's position of one period, world frame."""

    position_m: tuple[float, float, float]
    std_m: tuple[float, float, float]
    """√ of ``kalman.varX/Y/Z``, m."""


def onboard_position(values: Mapping[str, float]) -> OnboardPosition | None:
    """``stateEstimate.x/y/z`` and √``kalman.varX/Y/Z`` of one period, or None when a value is
    missing or not finite, or a variance not positive (the firmware bounds them to
    [1e-6, 100] m²)."""
    try:
        p = [float(values[k]) for k in POSITION]
        var = [float(values[k]) for k in POSITION_VAR]
    except KeyError:
        return None
    if not all(math.isfinite(v) for v in (*p, *var)) or min(var) <= 0.0:
        return None
    return OnboardPosition(
        (p[0], p[1], p[2]), (math.sqrt(var[0]), math.sqrt(var[1]), math.sqrt(var[2]))
    )


@dataclass
class SettleWatch:
    """Has the Kalman estimator settled since it was last reset? cflib's ``reset_estimator``
    (cflib/utils/reset_estimator.py, used by Bitcraze's mocap and Lighthouse examples): after
    ``kalman.resetEstimation``, each of ``kalman.varPX/PY/PZ`` must stay within ``spread``
    (max − min) over ``window_s``. Without measurements of its position the variances grow
    and never settle; a complementary estimator leaves them frozen, which would pass: the
    bridge selects the Kalman estimator before the reset.

    Args:
        window_s: how long the variances must stay within ``spread``, s.
        spread: their largest spread, m²/s².
    """

    window_s: float
    spread: float
    reset_s: float | None = None
    """Host clock of the last reset on this connection, s; None: none yet."""
    _samples: deque[tuple[float, tuple[float, float, float]]] = field(default_factory=deque)

    def reset(self, now_s: float) -> None:
        """The estimator was reset now: what came before no longer counts."""
        self.reset_s = now_s
        self._samples.clear()

    def forget(self) -> None:
        """A new connection: no reset on it yet."""
        self.reset_s = None
        self._samples.clear()

    def push(self, now_s: float, variances: Sequence[float]) -> None:
        """One sample of ``kalman.varPX/PY/PZ`` received at ``now_s`` (host clock)."""
        if self.reset_s is None or len(variances) != 3:
            return
        v = (float(variances[0]), float(variances[1]), float(variances[2]))
        if not all(math.isfinite(x) for x in v):
            self._samples.clear()  # a broken reading restarts the window
            return
        self._samples.append((now_s, v))
        # keep one sample at least window_s old, so that the samples span the window
        while len(self._samples) > 1 and self._samples[1][0] <= now_s - self.window_s:
            self._samples.popleft()

    def spreads(self) -> tuple[float, float, float] | None:
        """max − min of each variance over the samples kept, or None without samples."""
        if not self._samples:
            return None
        cols = list(zip(*(v for _, v in self._samples), strict=True))
        return (
            max(cols[0]) - min(cols[0]),
            max(cols[1]) - min(cols[1]),
            max(cols[2]) - min(cols[2]),
        )

    def settled(self, now_s: float, stale_s: float = 1.0) -> bool:
        """Reset on this connection, samples spanning ``window_s`` each within ``spread``, the
        latest no older than ``stale_s``."""
        spreads = self.spreads()
        if spreads is None or self.reset_s is None:
            return False
        first, last = self._samples[0][0], self._samples[-1][0]
        return (
            last - first >= self.window_s
            and now_s - last <= stale_s
            and all(s < self.spread for s in spreads)
        )


class Skip(ValueError):
    """This period yields no Telemetry; ``kind`` says why (counted, logged once per kind)."""

    def __init__(self, kind: str, detail: str) -> None:
        super().__init__(f"{kind}: {detail}")
        self.kind = kind


def build_telemetry(
    aligned: Aligned,
    plan: VariablePlan,
    section: CrazyflieSection,
    seq: int,
    slow: Mapping[str, float],
    mocap: MocapPose | None,
    now_s: float,
) -> Telemetry:
    """One period of log data → the contract's Telemetry, SI units.

    Args:
        aligned: the fast blocks of one period.
        plan: what is logged.
        section: ``[crazyflie]``.
        seq: the Telemetry's ``seq``.
        slow: latest values of the slow block (``pm.vbat``, ``supervisor.info``).
        mocap: latest motion-capture pose, or None.
        now_s: host monotonic clock, s (for the pose's age).

    ``position_m`` is the fresh motion-capture pose (``position_source`` ``mocap``), else, with
    ``onboard_position``, the onboard estimator's with its σ (``position_std_m``).

    Raises:
        Skip: non-finite readings (``bad_reading``), no attitude (``no_attitude``).
    """
    v = aligned.values
    try:
        acc_g = [float(v[k]) for k in ACC]
        gyro_dps = [float(v[k]) for k in GYRO]
        pwms = [float(v[k]) for k in plan.motors]
    except KeyError as exc:
        raise Skip("bad_reading", f"{exc.args[0]} missing from the period") from None
    if not all(math.isfinite(x) for x in (*acc_g, *gyro_dps, *pwms)):
        raise Skip("bad_reading", "non-finite accelerometer, gyro or motor value")
    stale_s = section.mocap_stale_s
    fresh = mocap if mocap is not None and now_s - mocap.received_s <= stale_s else None
    onboard = onboard_position(v) if plan.position else None
    if section.attitude_source == "mocap":
        raw = fresh.quat_wxyz if fresh is not None else None
        if raw is None:
            raise Skip("no_attitude", f"no motion-capture attitude within {stale_s} s")
        quat = normalise_quat(raw)
        if quat is None:
            raise Skip("bad_reading", "motion-capture quaternion not of unit norm")
    else:
        quat = normalise_quat([float(v[k]) for k in plan.attitude])
        if quat is None:
            raise Skip("bad_reading", "attitude quaternion not finite or not of unit norm")
    vbat = slow.get(VBAT)
    if section.thrust_model == "pwm_map":
        thrust = thrust_n(pwms, section.thrust_map)
    elif vbat is None or not math.isfinite(vbat) or vbat <= 0:
        raise Skip("no_vbat", f"thrust_model {section.thrust_model} needs pm.vbat")
    else:
        thrust = thrust_cubic_n(pwms, vbat, VMOTOR2THRUST[section.thrust_model])
    armed: bool | None = None
    if plan.armed and SUPERVISOR_INFO in slow:
        armed = bool((int(slow[SUPERVISOR_INFO]) >> SUPERVISOR_IS_ARMED_BIT) & 1)
    fields: dict[str, object] = {
        "seq": seq,
        "stamp_s": aligned.stamp_ms / 1000.0,
        # specific force, g -> m/s^2
        "accel_mps2": tuple(a * G_MPS2 for a in acc_g),
        "quat_wxyz": quat,
        "thrust_n": thrust,
        "gyro_rps": tuple(math.radians(g) for g in gyro_dps),
        "vbat_v": vbat if vbat is not None and math.isfinite(vbat) and vbat > 0 else None,
        # the estimator trusts the attitude's level only against a thrust axis calibrated
        # in the same frame: say which one this is
        "attitude_source": "external" if section.attitude_source == "mocap" else "onboard",
    }
    if fresh is not None:
        # Motion capture first: the onboard estimate fuses it (extpos) or another system.
        fields["position_m"] = fresh.position_m
        fields["position_source"] = "mocap"
    elif onboard is not None:
        fields["position_m"] = onboard.position_m
        fields["position_source"] = section.onboard_position
        # σ floored at 1 mm: the firmware's variance floor (1e-6 m²) is a bound, not a σ
        fields["position_std_m"] = tuple(max(s, 1e-3) for s in onboard.std_m)
    if armed is not None:
        fields["armed"] = armed
    return Telemetry.model_validate(fields, strict=False)


@dataclass(frozen=True, slots=True)
class SetpointCommand:
    """What the runner sends this tick."""

    position_m: tuple[float, float, float]
    yaw_deg: float
    motors_off: bool = False
    """A landing has ended on the floor: send a stop setpoint instead (motors off, no lock),
    then nothing."""


@dataclass(frozen=True, slots=True)
class _Ramp:
    start_m: tuple[float, float, float]
    target_m: tuple[float, float, float]
    t0_s: float
    duration_s: float
    land: bool

    def at(self, now_s: float) -> tuple[float, float, float]:
        f = (
            1.0
            if self.duration_s <= 0
            else min(1.0, max(0.0, (now_s - self.t0_s) / self.duration_s))
        )
        a, b = self.start_m, self.target_m
        return (a[0] + f * (b[0] - a[0]), a[1] + f * (b[1] - a[1]), a[2] + f * (b[2] - a[2]))

    def done(self, now_s: float) -> bool:
        return now_s >= self.t0_s + self.duration_s


LAND_SETTLE_S = 0.5
"""After the landing ramp reaches the floor, hold this long before the motors go off."""
MIN_JUMP_DT_S = 0.02
"""The shortest interval a setpoint jump is judged over (the setpoint period: two setpoints
delivered together are not a jump at infinite speed)."""


@dataclass(frozen=True, slots=True)
class Reach:
    """Where the tether lets the drone go: within ``length_m - margin_m`` of the base exit
    point, world frame, metres."""

    base_m: tuple[float, float, float]
    length_m: float
    margin_m: float = 0.05

    def within(self, position_m: Sequence[float]) -> bool:
        # |p - base| <= L - margin: a straight tether is the farthest the drone can be
        return math.dist(self.base_m, position_m) <= self.length_m - self.margin_m


Verdict = Literal[
    "accepted", "latched", "stale", "clock", "bad", "landing", "out_of_reach", "too_fast"
]
Phase = Literal["idle", "flying", "holding", "landing", "latched"]
"""What the gate is doing: ``idle`` (nothing sent: on the floor, or never commanded),
``flying`` (a setpoint or take-off ramp in force, the ground station heard), ``holding``
(the same, the ground station silent for ``silence_s``), ``landing`` (a landing ramp, then
motors off), ``latched`` (an emergency stop)."""
StopOutcome = Literal["latched", "landing", "motors_off"]


@dataclass
class CommandGate:
    """Watchdog, reach check, landings and stop latch between the bus's commands and the drone.

    * Nothing is sent until a Setpoint (or a take-off) arrives: the bridge never flies on its
      own.
    * Each tick re-sends the setpoint in force (the firmware levels and then cuts the motors
      when its stream of setpoints stops, so holding means repeating).
    * Ground-station silence (:attr:`heard_s`, the last Setpoint, Estimate or command, timed
      by the runner when it arrives): after ``silence_s`` the setpoint is held, never
      extrapolated (``holding``); after ``hold_s`` more the gate lands the drone itself:
      straight down to ``floor_z_m`` at ``land_speed_mps``, :data:`LAND_SETTLE_S` on the
      floor, then motors off (a stop setpoint, which does not lock the Crazyflie).
    * Setpoints are stamped on the drone's clock. One stamped more than ``watchdog_s``
      before the latest Telemetry, or before the setpoint in force, or arriving before any
      Telemetry, is stale; one more than ``watchdog_s`` after it is on another clock. One
      outside ``reach`` is out of reach; one jumping from the setpoint in force faster than
      ``max_speed_mps`` is too fast; one arriving during a landing is dropped (a landing is
      only replaced by a take-off or a Stop). All dropped and counted.
    * An emergency Stop latches: no setpoint is sent or accepted until :meth:`rearm`. A
      landing Stop lands (no latch). A link loss forgets the setpoint in force (after a
      reconnection the drone may be on the floor, and a held setpoint would lift it).

    Args:
        watchdog_s: freshness of setpoints against the telemetry, drone seconds.
        yaw_deg: yaw of the setpoints; None: the drone's yaw when the first setpoint arrives.
        silence_s: ground-station silence before holding, s.
        hold_s: holding before landing, s.
        land_speed_mps: descent speed of the gate's own landings, m/s.
        floor_z_m: where a landing ends, world z, m.
        reach: the tether's reach; None: not checked.
        max_speed_mps: fastest jump between setpoints, m/s.
    """

    watchdog_s: float
    yaw_deg: float | None = None
    silence_s: float = 0.1
    hold_s: float = 0.3
    land_speed_mps: float = 0.25
    floor_z_m: float = 0.0
    reach: Reach | None = None
    max_speed_mps: float = 1.0
    heard_s: float = -math.inf
    """Host clock when the ground station was last heard (set by the runner)."""
    latched: bool = False
    stop_reason: str = ""
    landing_reason: str = ""
    """Why the landing in progress (or the last one) began."""
    dropped: dict[str, int] = field(default_factory=dict)
    _position: tuple[float, float, float] | None = None
    _stamp_s: float = -math.inf
    _seen_stamp_s: float = -math.inf
    _received_s: float = -math.inf
    _yaw: float | None = None
    _ramp: _Ramp | None = None

    def on_setpoint(
        self,
        position_m: Sequence[float],
        stamp_s: float,
        now_s: float,
        telemetry_stamp_s: float | None,
        current_yaw_deg: float | None,
        current_position_m: Sequence[float] | None = None,
    ) -> Verdict:
        """Take a Setpoint from the bus.

        Args:
            position_m: world frame, metres.
            stamp_s: the Setpoint's stamp, on the drone's clock (the service stamps it with
                the Telemetry it was computed from).
            now_s: host monotonic clock, s.
            telemetry_stamp_s: ``stamp_s`` of the latest Telemetry published, or None.
            current_yaw_deg: the drone's yaw now (held when ``yaw_deg`` is None).
            current_position_m: the drone's measured position (motion capture), or None: a
                first setpoint may jump from it at most ``max_speed_mps`` × ``watchdog_s``.
        """
        verdict: Verdict = "accepted"
        if self.latched:
            verdict = "latched"
        elif len(position_m) != 3 or not all(math.isfinite(v) for v in position_m):
            verdict = "bad"
        elif self._ramp is not None and self._ramp.land:
            verdict = "landing"
        elif telemetry_stamp_s is None:
            verdict = "stale"  # no telemetry yet: nothing to judge its age against
        elif stamp_s < self._stamp_s or stamp_s < telemetry_stamp_s - self.watchdog_s:
            verdict = "stale"
        elif stamp_s > telemetry_stamp_s + self.watchdog_s:
            verdict = "clock"  # not on the drone's clock (a wall-clock stamp?)
        elif self.reach is not None and not self.reach.within(position_m):
            verdict = "out_of_reach"
        elif self._too_fast(position_m, stamp_s, now_s, current_position_m):
            verdict = "too_fast"
        if verdict in ("accepted", "out_of_reach", "too_fast"):
            # The stream's pace, refused setpoints included: a jump after a run of refusals
            # is judged over the setpoint period, not over the time since the last acceptance.
            self._seen_stamp_s = max(self._seen_stamp_s, stamp_s)
        if verdict == "accepted" and self._yaw is None:
            yaw = self.yaw_deg if self.yaw_deg is not None else current_yaw_deg
            if yaw is None:
                verdict = "bad"  # no attitude yet: cannot hold the drone's yaw
            else:
                self._yaw = yaw
        if verdict != "accepted":
            self._drop(verdict)
            return verdict
        x, y, z = (float(v) for v in position_m)
        self._ramp = None
        self._position = (x, y, z)
        self._stamp_s = stamp_s
        self._received_s = now_s
        self.heard_s = max(self.heard_s, now_s)
        return verdict

    def _too_fast(
        self,
        position_m: Sequence[float],
        stamp_s: float,
        now_s: float,
        current_position_m: Sequence[float] | None,
    ) -> bool:
        """The jump from the setpoint in force (or, for a first one, from the drone's
        measured position) is faster than ``max_speed_mps``."""
        origin = self.position_in_force(now_s)
        if origin is not None:
            # |Δp| > v_max · Δt, Δt between this setpoint's stamp and the previous one's (drone
            # clock), at least one setpoint period (two delivered together are no jump at
            # infinite speed); after a take-off ramp, the time since it began.
            previous_s = self._seen_stamp_s if math.isfinite(self._seen_stamp_s) else None
            dt_s = stamp_s - previous_s if previous_s is not None else now_s - self._received_s
            dt_s = max(dt_s, MIN_JUMP_DT_S)
        elif current_position_m is not None and len(current_position_m) == 3:
            origin = (
                float(current_position_m[0]),
                float(current_position_m[1]),
                float(current_position_m[2]),
            )
            dt_s = self.watchdog_s
        else:
            return False
        return math.dist(origin, position_m) > self.max_speed_mps * dt_s

    def on_stop(self, reason: str, now_s: float = 0.0, landing: bool = False) -> StopOutcome:
        """An emergency Stop latches: nothing more is sent until :meth:`rearm`. A landing Stop
        lands from the setpoint in force (motors off on the floor, no latch), or switches the
        motors off at once when nothing is in force.

        Returns:
            ``latched``; ``landing`` (a landing ramp began); ``motors_off`` (send a stop
            setpoint now).
        """
        if not landing:
            self.latched = True
            self.stop_reason = reason
            self._forget()
            return "latched"
        if self.latched:
            return "latched"  # an emergency stop is in force: a landing Stop lifts nothing
        if self._ramp is not None and self._ramp.land:
            return "landing"  # already on the way down
        if self._begin_landing(now_s, f"Stop ({reason})"):
            return "landing"
        self._forget()
        return "motors_off"

    def rearm(self) -> None:
        """The operator lifts the latch; a new setpoint is needed before anything is sent."""
        self.latched = False
        self.stop_reason = ""
        self._forget()

    def on_link_lost(self) -> None:
        self._forget()

    def silent_s(self, now_s: float) -> float:
        """Seconds since the ground station was last heard."""
        return now_s - max(self.heard_s, self._received_s)

    def holding(self, now_s: float) -> bool:
        """Flying on a setpoint, the ground station silent for more than ``silence_s``."""
        return self.phase(now_s) == "holding"

    def phase(self, now_s: float) -> Phase:
        """What the gate is doing now (see :data:`Phase`)."""
        if self.latched:
            return "latched"
        if self._position is None or self._yaw is None:
            return "idle"
        if self._ramp is not None and self._ramp.land:
            return "landing"
        if self.silent_s(now_s) > self.silence_s:
            return "holding"
        return "flying"

    def ramp(
        self,
        start_m: Sequence[float],
        target_m: Sequence[float],
        speed_mps: float,
        now_s: float,
        current_yaw_deg: float | None,
        land: bool = False,
        reason: str = "operator",
    ) -> Literal["accepted", "latched", "bad"]:
        """Fly a straight line at ``speed_mps`` (take-off, landing), then hold its end.

        A landing ramp ends with the motors off (after :data:`LAND_SETTLE_S`) and is replaced
        only by a take-off or a Stop. A Setpoint accepted during a take-off replaces it.
        """
        if self.latched:
            self._drop("latched")
            return "latched"
        pts = (*start_m, *target_m)
        yaw = (
            self._yaw
            if self._yaw is not None
            else (self.yaw_deg if self.yaw_deg is not None else current_yaw_deg)
        )
        if len(pts) != 6 or not all(math.isfinite(v) for v in pts) or yaw is None:
            self._drop("bad")
            return "bad"
        if not 0.0 < speed_mps <= 1.0:
            self._drop("bad")
            return "bad"
        a = (float(start_m[0]), float(start_m[1]), float(start_m[2]))
        b = (float(target_m[0]), float(target_m[1]), float(target_m[2]))
        dist = math.dist(a, b)
        self._yaw = yaw
        self._ramp = _Ramp(a, b, now_s, dist / speed_mps, land)
        self._position = a
        self._received_s = now_s
        self.heard_s = max(self.heard_s, now_s)
        if land:
            self.landing_reason = reason
        return "accepted"

    def position_in_force(self, now_s: float) -> tuple[float, float, float] | None:
        """Where the drone is being told to be now, or None."""
        if self._ramp is not None:
            return self._ramp.at(now_s)
        return self._position

    def tick(self, now_s: float) -> SetpointCommand | None:
        """The setpoint to send now, or None. Begins the silence landing when it is due."""
        if self.latched or self._position is None or self._yaw is None:
            return None
        if (self._ramp is None or not self._ramp.land) and self.silent_s(
            now_s
        ) > self.silence_s + self.hold_s:
            self._begin_landing(now_s, f"ground station silent for {self.silent_s(now_s):.2f} s")
        ramp = self._ramp
        if ramp is not None:
            if ramp.land and now_s > ramp.t0_s + ramp.duration_s + LAND_SETTLE_S:
                self._forget()
                return SetpointCommand(ramp.target_m, 0.0, motors_off=True)
            if not ramp.land and ramp.done(now_s):
                # A finished take-off is the setpoint in force. A ramp is not a fresh command:
                # the ground station must be heard during it and after it, as for a setpoint.
                self._ramp = None
                self._position = ramp.target_m
            else:
                return SetpointCommand(ramp.at(now_s), self._yaw)
        return SetpointCommand(self._position, self._yaw)

    def land(self, now_s: float, reason: str) -> bool:
        """Land from the setpoint in force now (the bridge's own decision, e.g. a silent link);
        False when nothing is in force, latched, or already landing."""
        if self.latched or (self._ramp is not None and self._ramp.land):
            return False
        return self._begin_landing(now_s, reason)

    def _begin_landing(self, now_s: float, reason: str) -> bool:
        start = self.position_in_force(now_s)
        if start is None or self._yaw is None:
            return False
        target = (start[0], start[1], min(start[2], self.floor_z_m))
        self.ramp(start, target, self.land_speed_mps, now_s, self._yaw, land=True, reason=reason)
        return True

    def _drop(self, verdict: str) -> None:
        self.dropped[verdict] = self.dropped.get(verdict, 0) + 1

    def _forget(self) -> None:
        self._ramp = None
        self._position = None
        self._stamp_s = -math.inf
        self._seen_stamp_s = -math.inf
        self._received_s = -math.inf
        self._yaw = None
