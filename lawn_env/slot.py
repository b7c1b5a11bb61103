"""The slot of B scenarios: :func:`step` over one compiled kernel.

:func:`step` (one slot of every scenario: ``step(params, state, decisions, draws)`` returns the new
state and the slot's record, its arguments untouched) and :func:`step_rows` (the same for chosen
rows). The compiled kernel composes the equations of :mod:`lawn_env.channel` (the link) and
:mod:`lawn_env.dynamics` (the control set, the transition, the lag, the measurement) and holds none
of its own; it reads :class:`SlotInputs` (which :func:`step` builds by name) and writes
:class:`SlotOutputs`, both handed over as the plain tuples numba types fastest, and it advances the
running sums through the columns :mod:`lawn_env.metrics` names.
"""

from __future__ import annotations

import operator
from typing import Any, NamedTuple, Protocol

import numba
import numpy as np

from . import channel, drone, dynamics
from .dynamics import measure
from .metrics import EFFORT, OUTAGE_P, PATH, PER_AGV, TRACKING
from .products import product_into
from .state import SLOT_CONSTANTS, Decisions, SimParams, SimState, SlotDraws, SlotRecord

__all__ = ["SlotInputs", "SlotOutputs", "step", "step_rows"]

# the first columns of dynamics.POSITION / VELOCITY / ACCELERATION in x~, as integers the kernels can index with
_POS0, _VEL0, _ACCEL0 = dynamics.POSITION.start, dynamics.VELOCITY.start, dynamics.ACCELERATION.start


def _array(dtype: numba.types.Type, ndim: int, out: bool = False, layout: str = "A") -> numba.types.Array:
    """An argument type of the slot kernel: inputs read-only in any layout (a step's states are
    views of the last step's rows), the parameters' matrices and the outputs C-contiguous."""
    return numba.types.Array(dtype, ndim, "C" if out else layout, readonly=not out)


class SlotInputs(NamedTuple):
    """What one slot reads: the state, the decisions and the draws of B scenarios (see :func:`_slot`)."""

    x_aug: np.ndarray  # (B, K, 6)
    increment: np.ndarray  # (B, K, 2)
    send: np.ndarray  # (B,) or (1,): whether the slot sends its commands
    power: np.ndarray  # (B, K)
    drone_next: np.ndarray  # (B, 2)
    fading: np.ndarray  # (B, K)
    reference: np.ndarray  # (B, K, T, 6)
    slot: np.ndarray  # (B,)
    applied: np.ndarray  # (B, K, 2): the applied acceleration (actuator lag)
    process_position: np.ndarray  # (B, K, 2), or (0, 0, 2) without process noise
    process_velocity: np.ndarray
    drone_prev: np.ndarray  # (B, 2)
    totals: np.ndarray  # (B, 5 + 3K)
    plan: np.ndarray  # (B, K, L, 2): the later increments each packet carries (buffered actuator), L = N_p - 1
    buffer: np.ndarray  # (B, K, L, 2): the AGVs' buffers; (B, K, 0, 2) under the hold actuator
    buffer_age: np.ndarray  # (B, K): how many of the buffer's increments have been played (L: spent)


class SlotConstants(Protocol):
    """A :data:`lawn_env.state.SLOT_CONSTANTS` record as the kernel reads it (its fields by name: numba types
    the record itself; this spells it for the type checker)."""

    lag_alpha: float
    accel_max: float
    altitude_sq: float
    c_d: float
    c_ce: float
    m: float
    step_t: np.ndarray  # (8, 8)
    cost_w: np.ndarray  # (8, 2)
    accel_effect_t: np.ndarray  # (2, 4)


class SlotOutputs(NamedTuple):
    """What one slot writes, new arrays the caller allocates (a compiled function's returned arrays
    cost more to hand back)."""

    rows: np.ndarray  # (2, B, K, 8): [x~[n+1], du applied] and [x~[n+1] - x~_ref[n+1], du]
    terms: np.ndarray  # (B, K, 2): e' Q1 e, du' Q2 du
    delivered: np.ndarray  # (B, K) bool
    outage: np.ndarray  # (B, K)
    applied_next: np.ndarray  # (B, K, 2), under lag
    costs: np.ndarray  # (B, 3)
    totals_next: np.ndarray  # (B, 5 + 3K)
    buffer_next: np.ndarray  # (B, K, L, 2)
    buffer_age_next: np.ndarray  # (B, K)
    slot_next: np.ndarray  # (B,): n + 1


_F, _B, _I = numba.types.float64, numba.types.boolean, numba.types.int64
_C = numba.types.Array(numba.from_dtype(SLOT_CONSTANTS), 1, "C", readonly=True)
#: The slot kernel's one signature: every caller (single, parallel and vector envs; fixed and random
#: paths; any role) converts to it, so the kernel compiles once instead of once per argument layout.
#: The records cross as plain tuples (numba's dispatcher types a plain tuple in C, a NamedTuple in
#: Python, about 2 us more per call) and are named on entry.
_SLOT_SIGNATURE = numba.types.none(
    numba.types.Tuple([_array(_F, 3), _array(_F, 3), _array(_B, 1), _array(_F, 2), _array(_F, 2), _array(_F, 2),
                       _array(_F, 4), _array(_I, 1), _array(_F, 3), _array(_F, 3), _array(_F, 3), _array(_F, 2),
                       _array(_F, 2), _array(_F, 4), _array(_F, 4), _array(_I, 2)]),
    _C,
    numba.types.Tuple([_array(_F, 4, out=True), _array(_F, 3, out=True), _array(_B, 2, out=True),
                       _array(_F, 2, out=True), _array(_F, 3, out=True), _array(_F, 2, out=True),
                       _array(_F, 2, out=True), _array(_F, 4, out=True), _array(_I, 2, out=True),
                       _array(_I, 1, out=True)]))


@numba.njit(cache=True, inline="always")
def _links(  # pragma: no cover - compiled
    inp: SlotInputs, c: SlotConstants, out: SlotOutputs, rows: np.ndarray,
) -> None:
    """Step 1: per link, the outage argument at the drone's next position, the outage probability,
    the delivery, and the packed row [x~, du applied] with du saturated: the command where it arrives;
    where none arrives (lost, or a slot without commands) zero under the hold actuator and the
    buffer's next increment under the buffered one (:func:`_played`)."""
    x_aug, increment, send, power, drone_next, fading = (inp.x_aug, inp.increment, inp.send, inp.power,
                                                         inp.drone_next, inp.fading)
    outage, delivered = out.outage, out.delivered
    k = x_aug.shape[1]
    buffered = inp.buffer.shape[2] > 0
    altitude_sq, c_d, c_ce, m, accel_max = c.altitude_sq, c.c_d, c.c_ce, c.m, c.accel_max
    for b in range(x_aug.shape[0]):
        sending = send[b % send.shape[0]]
        for i in range(k):
            r = b * k + i
            d2 = channel.link_distance_sq(x_aug[b, i, _POS0] - drone_next[b, 0],
                                          x_aug[b, i, _POS0 + 1] - drone_next[b, 1], altitude_sq)
            x = channel.link_argument(d2, power[b, i], c_d, c_ce)
            outage[b, i] = channel.outage_law(m, x, channel.OUTAGE)
            ok = channel.command_delivered(fading[b, i], x)
            delivered[b, i] = ok
            for j in range(6):
                rows[r, j] = x_aug[b, i, j]
            if buffered:
                for a in range(2):
                    du = increment[b, i, a] if sending and ok else _played(inp.buffer, inp.buffer_age, b, i, a)
                    rows[r, 6 + a] = dynamics.saturate(x_aug[b, i, _ACCEL0 + a], du, accel_max)
                continue
            for a in range(2):
                du = dynamics.saturate(x_aug[b, i, _ACCEL0 + a], increment[b, i, a], accel_max) if sending else 0.0
                rows[r, 6 + a] = du * (1.0 if ok else 0.0)


@numba.njit(cache=True, inline="always")
def _played(buffer: np.ndarray, age: np.ndarray, b: int, i: int, a: int) -> float:  # pragma: no cover - compiled
    """The increment AGV i of scenario b plays without a packet under the buffered actuator: its
    buffer's next one, zero (a hold) once the buffer is spent."""
    j = age[b, i]
    return buffer[b, i, j, a] if j < buffer.shape[2] else 0.0


@numba.njit(cache=True, inline="always")
def _buffers(inp: SlotInputs, out: SlotOutputs) -> None:  # pragma: no cover - compiled
    """Step 1b (buffered actuator): a delivered packet replaces the AGV's buffer with the later
    increments it carries (none played yet); otherwise the buffer advances by the one it played."""
    buffer, age, plan, send, delivered = inp.buffer, inp.buffer_age, inp.plan, inp.send, out.delivered
    length = buffer.shape[2]
    for b in range(buffer.shape[0]):
        sending = send[b % send.shape[0]]
        for i in range(buffer.shape[1]):
            fresh = sending and delivered[b, i]
            out.buffer_age_next[b, i] = 0 if fresh else min(age[b, i] + 1, length)
            for j in range(length):
                for a in range(2):
                    out.buffer_next[b, i, j, a] = plan[b, i, j, a] if fresh else buffer[b, i, j, a]


@numba.njit(cache=True, inline="always")
def _lag(x_aug: np.ndarray, applied: np.ndarray, lag_alpha: float, applied_next: np.ndarray, flat: np.ndarray,
         accel_effect_t: np.ndarray) -> None:  # pragma: no cover - compiled
    """Step 3 (actuator lag): the AGV moves with the applied acceleration instead of the commanded
    u[n]; the difference enters through A~'s acceleration columns."""
    num, k = x_aug.shape[0], x_aug.shape[1]
    gap = np.empty((num * k, 2))
    for b in range(num):
        for i in range(k):
            r = b * k + i
            for a in range(2):
                commanded = x_aug[b, i, _ACCEL0 + a] + flat[r, 6 + a]
                applied_next[b, i, a] = dynamics.lagged_acceleration(applied[b, i, a], commanded, lag_alpha)
                gap[r, a] = applied_next[b, i, a] - commanded
    correction = np.empty((num * k, accel_effect_t.shape[1]))
    product_into(gap, accel_effect_t, correction)
    for r in range(num * k):
        for j in range(4):
            flat[r, j] += correction[r, j]


@numba.njit(cache=True, inline="always")
def _process_noise(  # pragma: no cover - compiled
    packed: np.ndarray, process_position: np.ndarray, process_velocity: np.ndarray,
) -> None:
    """Step 3 (process noise): added to the next positions and velocities where drawn."""
    k = packed.shape[1]
    for b in range(process_position.shape[0]):
        for i in range(k):
            for a in range(2):
                packed[b, i, _POS0 + a] += process_position[b, i, a]
    for b in range(process_velocity.shape[0]):
        for i in range(k):
            for a in range(2):
                packed[b, i, _VEL0 + a] += process_velocity[b, i, a]


@numba.njit(cache=True, inline="always")
def _errors(packed: np.ndarray, reference: np.ndarray, slot: np.ndarray, err: np.ndarray,
            squares: np.ndarray) -> None:  # pragma: no cover - compiled
    """Step 4: the packed error against the reference at slot n+1, and its squares."""
    num, k = packed.shape[0], packed.shape[1]
    for b in range(num):
        s = slot[b] + 1
        for i in range(k):
            r = b * k + i
            for j in range(8):
                e = packed[b, i, j] - reference[b, i, s, j] if j < 6 else packed[b, i, j]
                err[b, i, j] = e
                squares[r, j] = e * e


@numba.njit(cache=True, inline="always")
def _accumulate(inp: SlotInputs, out: SlotOutputs, err: np.ndarray) -> None:  # pragma: no cover - compiled
    """Step 5: the slot's stage costs summed over AGVs (left to right) and the episode's running
    sums (:data:`lawn_env.metrics.TOTALS`, ``out.totals_next`` holding the last slot's) advanced, the
    outage and power sums on command slots only."""
    terms, outage, delivered, costs, totals = out.terms, out.outage, out.delivered, out.costs, out.totals_next
    send, power, drone_next, drone_prev = inp.send, inp.power, inp.drone_next, inp.drone_prev
    num, k = terms.shape[0], terms.shape[1]
    for b in range(num):
        sent = 1.0 if send[b % send.shape[0]] else 0.0
        t, e, o = terms[b, 0, 0], terms[b, 0, 1], outage[b, 0]
        for i in range(1, k):
            t += terms[b, i, 0]
            e += terms[b, i, 1]
            o += outage[b, i]
        costs[b, 0], costs[b, 1], costs[b, 2] = t, e, t + e
        totals[b, TRACKING] += t
        totals[b, EFFORT] += e
        totals[b, OUTAGE_P] += sent * o
        sx, sy = drone_next[b, 0] - drone_prev[b, 0], drone_next[b, 1] - drone_prev[b, 1]
        totals[b, PATH] += np.sqrt(sx * sx + sy * sy)
        sq_error, outages, power_sum, largest = PER_AGV, PER_AGV + k, PER_AGV + 2 * k, PER_AGV + 3 * k  # blocks
        for i in range(k):
            sq = err[b, i, 0] ** 2 + err[b, i, 1] ** 2
            totals[b, sq_error + i] += sq
            totals[b, outages + i] += 0.0 if delivered[b, i] else sent
            totals[b, power_sum + i] += sent * power[b, i]
            totals[b, largest] = max(totals[b, largest], sq)


@numba.njit([_SLOT_SIGNATURE], cache=True)
def _slot(  # pragma: no cover - compiled
    inputs: tuple[np.ndarray, ...], constants: np.ndarray, outputs: tuple[np.ndarray, ...],
) -> None:
    """One slot of B scenarios (see :func:`step`): 1. the links (:func:`_links`) and, under the
    buffered actuator, the buffers (:func:`_buffers`); 2. the transition,
    [x~[n+1], du] = [x~, du applied] @ step_t (:func:`lawn_env.products.product_into`: one summation
    order on every machine and batch size, not BLAS); 3. the disturbance mode's actuator lag (``lag_alpha`` >=
    0) and process noise (where the arrays are not empty); 4. the packed error and the stage terms (e' Q1 e, du'
    Q2 du) = err^2 @ cost_w; 5. the costs and the
    running sums. Reads ``inputs`` (the :class:`SlotInputs` fields) and the :data:`SLOT_CONSTANTS`
    record (its scalars and matrices); writes ``outputs`` (the :class:`SlotOutputs` fields)."""
    inp, out, c = SlotInputs(*inputs), SlotOutputs(*outputs), constants[0]
    num, k = inp.x_aug.shape[0], inp.x_aug.shape[1]
    n = num * k
    rows = np.empty((n, 8))
    _links(inp, c, out, rows)
    if inp.buffer.shape[2] > 0:
        _buffers(inp, out)
    packed_rows, err = out.rows[0], out.rows[1]
    flat = packed_rows.reshape((n, 8))
    product_into(rows, c.step_t, flat)
    if c.lag_alpha >= 0.0:
        _lag(inp.x_aug, inp.applied, c.lag_alpha, out.applied_next, flat, c.accel_effect_t)
    _process_noise(packed_rows, inp.process_position, inp.process_velocity)
    squares = np.empty((n, 8))
    _errors(packed_rows, inp.reference, inp.slot, err, squares)
    product_into(squares, c.cost_w, out.terms.reshape((n, 2)))
    out.totals_next[:] = inp.totals
    _accumulate(inp, out, err)
    for b in range(num):
        out.slot_next[b] = inp.slot[b] + 1


_NO_NOISE = np.zeros((0, 0, 2))  # the slot kernel's "no process noise"
_NO_PLAN = np.zeros((0, 0, 0, 2))  # the slot kernel's plan under the hold actuator
#: :class:`SlotInputs` from a dict of them by name, as the plain tuple the kernel takes (in the fields' order):
#: built by name at the price of a dict display (a NamedTuple's keywords cost twice as much per slot)
_INPUTS = operator.itemgetter(*SlotInputs.__annotations__)
# x~[n+1], the error x~[n+1] - x~_ref[n+1] and du applied in the kernel's rows (2, B, K, 8), as prebuilt indices
# (one indexing per view, not two)
_X_NEXT, _ERROR, _APPLIED = ((0, slice(None), slice(None), slice(0, 6)), (1, slice(None), slice(None), slice(0, 6)),
                             (0, slice(None), slice(None), slice(6, 8)))


def step(params: SimParams, state: SimState, decisions: Decisions, draws: SlotDraws) -> tuple[SimState, SlotRecord]:
    """Advance every scenario one slot: a new state and the slot's record; ``state`` and the
    arguments are not modified. Commands are saturated to the acceleration bound and sent from the
    drone's next position q[n] to the AGVs at their slot-n positions; they arrive with the drawn
    fading. The disturbance mode (MODEL.md §7) runs through the same equations: wind moves the
    drone after its planned move, commands go out only every ``control_period_slots``, the applied
    acceleration lags the commanded one, process noise perturbs the AGVs and measurement noise
    what the policies observe. The decisions may come in any real dtype (the kernel's is float64)."""
    d = params.disturbance
    drone_next = np.asarray(decisions.drone_next, dtype=np.float64)
    if params.disturbed:
        wind = np.asarray(d.wind_mps, dtype=float)
        if draws.gust is not None:
            wind = wind + draws.gust
        drone_next = drone.drift(drone_next, wind, params.slot_s, params.area_lo, params.area_hi)
    x_aug = state.x_aug
    num, k = x_aug.shape[0], x_aug.shape[1]
    increment = np.asarray(decisions.increment, dtype=np.float64)
    power = np.asarray(decisions.power_w, dtype=np.float64)
    send = state.slot % params.command_period == 0 if params.disturbed else params.every_slot
    rows, terms = np.empty((2, num, k, 8)), np.empty((num, k, 2))
    delivered, outage_p = np.empty((num, k), np.bool_), np.empty((num, k))
    applied = state.applied if params.lag_alpha < 0.0 else np.empty((num, k, 2))
    costs, totals = np.empty((num, 3)), np.empty(state.totals.shape)
    plan, buffer_next, age_next = _NO_PLAN, state.buffer, state.buffer_age  # the hold actuator's: unread
    if params.buffer_length:
        plan = _plan(params, decisions.plan, num, k)
        buffer_next, age_next = np.empty(state.buffer.shape), np.empty(state.buffer_age.shape, np.int64)
    inputs = _INPUTS({  # SlotInputs by name
        "x_aug": x_aug, "increment": increment, "send": send, "power": power, "drone_next": drone_next,
        "fading": draws.fading, "reference": state.reference, "slot": state.slot, "applied": state.applied,
        "process_position": _NO_NOISE if draws.process_position is None else draws.process_position,
        "process_velocity": _NO_NOISE if draws.process_velocity is None else draws.process_velocity,
        "drone_prev": state.drone_position, "totals": state.totals, "plan": plan, "buffer": state.buffer,
        "buffer_age": state.buffer_age})
    slot = np.empty(num, np.int64)
    _slot(inputs, params.constants,
          (rows, terms, delivered, outage_p, applied, costs, totals, buffer_next, age_next, slot))  # SlotOutputs
    x_next, error, applied_increment = rows[_X_NEXT], rows[_ERROR], rows[_APPLIED]
    x_obs, error_obs = x_next, error
    if draws.measurement_position is not None and draws.measurement_velocity is not None:  # drawn together
        x_obs, error_obs = measure(x_next, error, draws.measurement_position, draws.measurement_velocity)
    new = SimState(x_aug=x_next, tracking_error=error, x_obs=x_obs, error_obs=error_obs, applied=applied,
                   drone_position=drone_next, slot=slot, last_power_w=power, last_delivered=delivered,
                   last_outage_probability=outage_p, reference=state.reference, paths=state.paths, totals=totals,
                   buffer=buffer_next, buffer_age=age_next)
    record = SlotRecord(terms, delivered, outage_p, applied_increment, power, drone_next, costs)  # its field order
    return new, record


def _plan(params: SimParams, plan: np.ndarray | None, num: int, k: int) -> np.ndarray:
    """The slot kernel's ``plan`` (B, K, L, 2) float64 of a decision's under the buffered actuator
    (zeros when it has none), each increment clipped to the increment bound Delta-a_max: the packet
    carries the plan inside the control set, whatever a planner left unbounded."""
    length = params.buffer_length
    if plan is None:
        return np.zeros((num, k, length, 2))
    given = np.asarray(plan, dtype=np.float64)
    if given.shape != (num, k, length, 2):
        raise ValueError(f"decisions.plan has shape {given.shape}; the buffered actuator takes the later increments "
                         f"of each AGV's sequence, ({num}, {k}, {length}, 2) (N_p - 1 = {length})")
    bound = params.config.control.accel_increment_max_mps2
    return np.clip(given, -bound, bound)


#: The state's arrays with a leading batch axis that a step replaces (the reference and the paths it
#: never changes); ``x_obs`` and ``error_obs`` may be the same arrays as ``x_aug`` and ``tracking_error``.
_STEPPED = ("x_aug", "tracking_error", "x_obs", "error_obs", "applied", "drone_position", "slot", "last_power_w",
            "last_delivered", "last_outage_probability", "totals", "buffer", "buffer_age")


def step_rows(params: SimParams, state: SimState, decisions: Decisions, draws: SlotDraws,
              rows: np.ndarray) -> tuple[SimState, SlotRecord]:
    """:func:`step` of the scenarios ``rows`` (a (B,) mask) alone, with their rows of the decisions
    and of the draws (drawn for every scenario, so each scenario's numbers do not depend on which
    others step); the other scenarios keep their state, and their record rows are zeros. A vector
    env's scenarios restarted this slot do not step."""
    idx = np.flatnonzero(rows)
    sub = SimState(**{name: getattr(state, name)[idx] for name in (*_STEPPED, "reference")},
                   paths=[state.paths[i] for i in idx.tolist()])
    if state.x_obs is state.x_aug:  # without measurement noise, the observed state is the true one
        sub.x_obs = sub.x_aug
    if state.error_obs is state.tracking_error:
        sub.error_obs = sub.tracking_error
    # each field's rows, field by field (the arrays that are None stay None)
    taken: list[Any] = [None if a is None else np.asarray(a)[idx] for a in decisions]
    drawn: list[Any] = [None if d is None else d[idx] for d in draws]
    new_sub, record = step(params, sub, Decisions(*taken), SlotDraws(*drawn))
    merged: dict[str, Any] = {}
    for name in _STEPPED:
        new = getattr(new_sub, name)
        if name == "x_obs" and new is new_sub.x_aug:
            merged[name] = merged["x_aug"]
        elif name == "error_obs" and new is new_sub.tracking_error:
            merged[name] = merged["tracking_error"]
        else:
            merged[name] = getattr(state, name).copy()
            merged[name][idx] = new
    full = SlotRecord(*(np.zeros((state.num_envs, *a.shape[1:]), a.dtype) for a in record))
    for whole, part in zip(full, record, strict=True):
        whole[idx] = part
    return SimState(**merged, reference=state.reference, paths=state.paths), full

