"""Observation and action encodings shared by every environment and by the policies.

Actions are normalized to [-1, 1]; the maps below turn them into physical decisions and back
(the inverse maps let planners that think in watts and metres drive the environments).

* Increments: ``Delta-u = a * Delta-a_max`` per axis; the simulator then saturates it so that
  ``|u[n-1] + Delta-u| <= a_max`` (the control set, by saturation).
* Power: ``w = (a + 1) / 2`` in [0, 1]^K, ``p = P_max * w / max(1, sum w)``. Every feasible
  split (p >= 0, sum p <= P_max) is reachable, sum p <= P_max always holds, and the zero action
  is the equal split for K >= 2.
* Drone: ``v = a * V_max`` per axis, clipped radially to ``||v|| <= V_max``; the drone moves
  ``v * Delta-tau`` and is clipped into the area.
* Plans (``lawn/Joint-v1`` under ``control.actuator="buffer"``): after the drone's two entries, the
  rest of every AGV's planned sequence, ``a * Delta-a_max`` per entry: AGV by AGV, the increments
  planned for slots n+1 .. n+N_p-1, x then y (2 K (N_p - 1) entries); the packet carries them and a
  lost packet's AGV plays them (MODEL.md §3). The zero plan holds, as the hold actuator does.

Observations are float32 vectors: K blocks of :attr:`ObservationLayout.agv_features` features
followed by 3 global features (see :meth:`ObservationLayout.feature_names`).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, NamedTuple, Protocol

import gymnasium as gym
import numba
import numpy as np

from .drone import move_rows
from .dynamics import POSITION
from .state import Decisions, buffer_queue

if TYPE_CHECKING:
    from .config import ScenarioConfig
    from .core import Simulation
    from .mpc import OutageAwareMPC

__all__ = [
    "ObservationLayout",
    "SlotTable",
    "ActionCodec",
    "DirectActions",
    "ACTION_LIMITS",
    "ROLES",
    "check_action",
    "power_rows",
    "direct_rows",
    "POSITION_ERROR_SCALE_M",
    "VELOCITY_SCALE_MPS",
]

#: Reference positions are observed relative to the AGV, divided by this (m).
POSITION_ERROR_SCALE_M = 10.0
#: Velocities are divided by this (m/s).
VELOCITY_SCALE_MPS = 5.0


def check_action(action: Any, size: int, name: str = "action", num_envs: int | None = None) -> np.ndarray:
    """Validate normalized actions as Gymnasium's ``Box.contains`` would: real numbers (a float or
    integer array, or a list of numbers) of shape exactly ``(size,)``, or ``(num_envs, size)`` for
    a batch, finite, inside [-1, 1]. Complex, boolean, string and object inputs and other shapes
    raise ``ValueError`` naming ``name``, the expected shape and dtype; a bad entry is named by its
    index (and, in a batch, its env's). Returns float64."""
    shape = (size,) if num_envs is None else (num_envs, size)
    try:
        a = np.asarray(action)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name} must be a real array of shape {shape}, float32: {exc}") from None
    if a.dtype.kind not in "fiu":
        raise ValueError(f"{name} has dtype {a.dtype} ({type(action).__name__}); expected real numbers of shape "
                         f"{shape}, float32 (complex, boolean and string actions are not accepted)")
    if a.shape != shape:
        raise ValueError(f"{name} has shape {a.shape}; expected {shape}, float32, with entries in [-1, 1]")
    a = np.ascontiguousarray(a, dtype=np.float64)
    if _first_outside(a) >= 0:
        raise ValueError(_outside_message(a, name, batched=num_envs is not None))
    return a


#: How many bad entries an action's error lists (it says how many there are in all).
SHOWN_BAD_ENTRIES = 8


def _outside_message(a: np.ndarray, name: str, batched: bool) -> str:
    """The error for entries of ``a`` outside [-1, 1] or NaN: how many there are, and the first
    :data:`SHOWN_BAD_ENTRIES` by index (``env i: action entry j`` in a batch) and value."""
    bad = np.argwhere(~((a >= -1.0) & (a <= 1.0)))
    n, shown = len(bad), bad[:SHOWN_BAD_ENTRIES]
    tail = "actions are normalized (see the environment's Action Space)"
    if batched:
        items = [f"env {e}: {name} entry {j} = {float(a[e, j])!r}" for e, j in shown.tolist()]
        if n == 1:
            return f"{items[0]} is outside [-1, 1] or not finite; {tail}"
        envs = len(np.unique(bad[:, 0]))
        which = f"; the first {len(shown)}:" if n > len(shown) else ":"
        return (f"{n} {name} entries (in {envs} env{'s' if envs > 1 else ''}) are outside [-1, 1] or not finite"
                f"{which} {', '.join(items)}; {tail}")
    index = shown[:, 0].tolist()
    which = f"; the first {len(shown)}:" if n > len(shown) else ":"
    return (f"{n} {name} {'entry is' if n == 1 else 'entries are'} outside [-1, 1] or not finite{which} "
            f"entries {index} = {a[index].tolist()}; {tail}")


@numba.njit(cache=True)
def power_rows(a: np.ndarray, budget: float, out: np.ndarray) -> None:  # pragma: no cover - compiled
    """The power split of the direct scheme on rows of actions (B, K), written to ``out``:
    ``w = (a + 1) / 2``, ``p = P_max w / max(1, sum w)``, the sum left to right whatever K."""
    k = a.shape[1]
    for b in range(a.shape[0]):
        total = a[b, 0]
        for i in range(1, k):
            total += a[b, i]
        total = 0.5 * (total + k)
        scale = 0.5 * budget / (total if total >= 1.0 else 1.0)
        for i in range(k):
            out[b, i] = (a[b, i] + 1.0) * scale


@numba.njit(cache=True)
def direct_rows(a: np.ndarray, increment_size: int, limits: np.ndarray, position: np.ndarray, increment: np.ndarray,
                power: np.ndarray, drone_next: np.ndarray) -> None:  # pragma: no cover - compiled
    """The direct scheme's decisions of checked actions (B, size) under ``limits`` (a record of
    :data:`ACTION_LIMITS`), written to ``increment`` (B, K, 2) (nothing when ``increment_size`` is 0),
    ``power`` (B, K) (:func:`power_rows`) and ``drone_next`` (B, 2) (:func:`lawn_env.drone.move_rows`
    at the velocities ``a * V_max``): arrays the caller allocates (cheaper than a compiled function's
    returned arrays)."""
    lim = limits[0]
    num, k = a.shape[0], power.shape[1]
    velocity = np.empty((num, 2))
    for b in range(num):
        for i in range(increment_size // 2):
            increment[b, i, 0] = a[b, 2 * i] * lim.increment_max
            increment[b, i, 1] = a[b, 2 * i + 1] * lim.increment_max
        velocity[b, 0] = a[b, increment_size + k] * lim.max_speed
        velocity[b, 1] = a[b, increment_size + k + 1] * lim.max_speed
    power_rows(a[:, increment_size : increment_size + k], lim.power_budget, power)
    move_rows(position, velocity, lim.max_speed, lim.slot_s, lim.x0, lim.x1, lim.y0, lim.y1, drone_next)


@numba.njit(cache=True)
def _first_outside(a: np.ndarray) -> int:  # pragma: no cover - compiled
    """The flat index of the first entry outside [-1, 1] or NaN, -1 when there is none."""
    flat = a.ravel()
    for i in range(flat.size):
        if not (flat[i] >= -1.0 and flat[i] <= 1.0):
            return i
    return -1


#: What the direct scheme's decode needs of the config, by name (a record, for the compiled decode):
#: the increment bound Delta-a_max, the power budget P_max, V_max, the slot and the area.
ACTION_LIMITS = np.dtype([("increment_max", "f8"), ("power_budget", "f8"), ("max_speed", "f8"), ("slot_s", "f8"),
                          ("x0", "f8"), ("x1", "f8"), ("y0", "f8"), ("y1", "f8")])

#: What an action of each role decides: ``joint`` (increments, power, drone: Joint-v1),
#: ``comm`` (power and drone: Comm-v1 and the parallel env's drone).
ROLES = ("joint", "comm")


class ActionCodec:
    """The normalized actions of one role under one scheme: ``decode`` turns checked actions in
    [-1, 1] into :class:`~lawn_env.core.Decisions`, ``encode`` is its inverse (exact for decisions
    the scheme can express; otherwise the nearest action, clipped). One codec per scheme:
    :class:`DirectActions` (the v0 actions) and
    :class:`~lawn_env.interface.AnchoredActions`; :func:`lawn_env.interface.action_codec` picks an
    interface's. The envs decode with it and the policies encode with it.

    The state arguments are the measured augmented states (K, 6), the reference window
    (K, N_p+1, 6) and the drone's current position (2,) (:class:`~lawn_env.core.Snapshot` and the
    observation's decode carry the same arrays), or a batch of them with a leading B axis.
    """

    scheme = ""
    #: Whether decoding needs the reference window.
    needs_reference = False
    #: The MPC the scheme's anchor plans with (None: none).
    mpc: OutageAwareMPC | None = None
    #: The entries of the AGVs' plans at the action's end (:class:`DirectActions` under the buffered actuator)
    plan_size = 0

    def __init__(self, config: ScenarioConfig, role: str = "joint"):
        if role not in ROLES:
            raise ValueError(f"role={role!r}; valid: {', '.join(ROLES)}")
        k = config.num_agvs
        self.role, self.num_agvs = role, k
        self.increment_size = 2 * k if role == "joint" else 0
        #: L = N_p - 1, the later increments a packet carries under the buffered actuator (0 under hold)
        self.buffer_length = config.control.buffer_length
        self.size = self.increment_size + k + 2
        self.space = gym.spaces.Box(-1.0, 1.0, shape=(self.size,), dtype=np.float32)
        self.limits = np.array([(config.control.accel_increment_max_mps2, config.power_budget_w,
                                 config.drone.max_speed_mps, config.slot_s, *config.area_m)], dtype=ACTION_LIMITS)
        self.limits.setflags(write=False)
        x0, x1, y0, y1 = config.area_m
        self.area = (float(x0), float(x1), float(y0), float(y1))

    def reset(self, which: np.ndarray | None = None) -> None:
        """Start an episode (``which``: a mask over a batch's scenarios, all when None)."""

    def decode(self, actions: np.ndarray, x_aug: np.ndarray, reference: np.ndarray | None,
               drone_position: np.ndarray, slot: int | np.ndarray | None = None) -> Decisions:
        """The decisions of checked actions: one scenario (action (size,), states (K, 6), reference
        window (K, N_p+1, 6), drone position (2,), slot) or a batch of B (the same with a leading B
        axis, ``slot`` (B,): the scenarios' slots, for move blocking with a control period); the
        Decisions's arrays have the same leading axes."""
        a = np.asarray(actions)
        if a.ndim > 1:
            return self._decode_rows(a, x_aug, reference, drone_position, slot)
        ref = None if reference is None else reference[None]
        x = x_aug if x_aug is None else np.asarray(x_aug)[None]
        d = self._decode_rows(a[None], x, ref, np.asarray(drone_position)[None],
                              None if slot is None else np.asarray(slot).reshape(1))
        return Decisions(None if d.increment is None else d.increment[0], d.power_w[0], d.drone_next[0],
                         None if d.plan is None else d.plan[0])

    def _decode_rows(self, actions: np.ndarray, x_aug: np.ndarray, reference: np.ndarray | None,
                     drone_position: np.ndarray, slot: int | np.ndarray | None) -> Decisions:  # pragma: no cover
        raise NotImplementedError

    def encode(self, decision: Decisions, x_aug: np.ndarray, reference: np.ndarray | None,
               drone_position: np.ndarray, slot: int | None = None) -> np.ndarray:  # pragma: no cover - interface
        """The action (float32) of one scenario that decodes to ``decision``."""
        raise NotImplementedError


_NO_INCREMENT = np.empty((0, 0, 2))  # direct_rows' increment output of a role without increments


class DirectActions(ActionCodec):
    """The v0 actions (module docstring): increments ``a * Delta-a_max``, power ``w = (a + 1) / 2``,
    ``p = P_max w / max(1, sum w)``, drone velocity ``a * V_max``; under the buffered actuator
    Joint's action ends with the AGVs' plans, ``a * Delta-a_max``."""

    scheme = "direct"

    def __init__(self, config: ScenarioConfig, role: str = "joint"):
        super().__init__(config, role)
        #: The plans' entries at the action's end: 2 K (N_p - 1) for Joint under the buffered actuator, else 0
        self.plan_size = self.increment_size * self.buffer_length
        if self.plan_size:
            self.size += self.plan_size
            self.space = gym.spaces.Box(-1.0, 1.0, shape=(self.size,), dtype=np.float32)

    def _decode_rows(self, actions: np.ndarray, x_aug: np.ndarray, reference: np.ndarray | None,
                     drone_position: np.ndarray, slot: int | np.ndarray | None) -> Decisions:
        num, k = actions.shape[0], self.num_agvs
        increment = np.empty((num, k, 2)) if self.increment_size else None
        power, drone_next = np.empty((num, k)), np.empty((num, 2))
        flat = np.ascontiguousarray(actions, dtype=np.float64)
        direct_rows(flat, self.increment_size, self.limits, np.ascontiguousarray(drone_position, dtype=np.float64),
                    _NO_INCREMENT if increment is None else increment, power, drone_next)
        plan = None
        if self.plan_size:
            plan = flat[:, self.size - self.plan_size :].reshape(num, k, self.buffer_length, 2)
            plan = plan * self.limits[0]["increment_max"]
        return Decisions(increment, power, drone_next, plan)

    def encode(self, decision: Decisions, x_aug: np.ndarray | None, reference: np.ndarray | None,
               drone_position: np.ndarray, slot: int | None = None) -> np.ndarray:
        """The action of ``decision`` (the state but the drone's position is not needed): power
        ``a = 2 p / P_max - 1`` (a feasible split, else ``ValueError``), the drone's velocity to its
        next position over V_max, increments over Delta-a_max, clipped to [-1, 1]."""
        lim = self.limits[0]
        p = np.asarray(decision.power_w, dtype=float)
        if np.any(p < -1e-12) or p.sum() > lim["power_budget"] * (1 + 1e-9):
            raise ValueError(f"power_w={p.tolist()} is not a feasible split of P_max={lim['power_budget']} W")
        move = np.asarray(decision.drone_next, dtype=float) - np.asarray(drone_position, dtype=float)
        parts = [2.0 * p / lim["power_budget"] - 1.0, move / (lim["slot_s"] * lim["max_speed"])]
        if self.increment_size:
            parts.insert(0, np.asarray(decision.increment, dtype=float).reshape(-1) / lim["increment_max"])
        if self.plan_size:
            plan = np.zeros(self.plan_size) if decision.plan is None else np.asarray(decision.plan, dtype=float)
            if plan.size != self.plan_size:
                raise ValueError(f"decision.plan has shape {plan.shape}; this action carries "
                                 f"({self.num_agvs}, {self.buffer_length}, 2) (K, N_p - 1, 2)")
            parts.append(plan.reshape(-1) / lim["increment_max"])
        action: np.ndarray = np.clip(np.concatenate(parts), -1.0, 1.0).astype(np.float32)
        return action


#: What the compiled encode reads of an :class:`ObservationLayout`, by name (one record): where
#: each per-AGV feature starts in an AGV's block (from the layout's table), the block's size and
#: window count, and the scalings: states ``x * state_scale - state_shift``, errors and reference
#: windows ``* reference_scale``, positions ``(p - center) * inverse_half_extent``, powers
#: ``* inverse_budget``.
OBS_CODEC = np.dtype([("state", "i8"), ("error", "i8"), ("reference", "i8"), ("relative_to_drone", "i8"),
                      ("outage_probability", "i8"), ("delivered", "i8"), ("power", "i8"), ("agv_features", "i8"),
                      ("window", "i8"), ("state_scale", "f8", 6), ("state_shift", "f8", 6),
                      ("reference_scale", "f8", 6), ("center", "f8", 2), ("inverse_half_extent", "f8", 2),
                      ("inverse_budget", "f8")])


class ObsCodec(Protocol):
    """An :data:`OBS_CODEC` record as the kernels read it (its fields by name: numba types the record
    itself; this spells it for the type checker): the features' offsets, then their scales."""

    state: int
    error: int
    reference: int
    relative_to_drone: int
    outage_probability: int
    delivered: int
    power: int
    agv_features: int
    window: int
    state_scale: np.ndarray
    state_shift: np.ndarray
    reference_scale: np.ndarray
    center: np.ndarray
    inverse_half_extent: np.ndarray
    inverse_budget: float


@numba.njit(cache=True)
def _encode_rows(  # noqa: PLR0913 - a compiled kernel (up to 12 arguments)
    out: np.ndarray, table: np.ndarray, slot: np.ndarray, state: tuple[np.ndarray, ...], reference: np.ndarray,
    codec: np.ndarray, num_slots: int, bound: float, clip_table: bool,
) -> None:  # pragma: no cover - compiled
    """Every observation row, each feature computed in float64 as :meth:`ObservationLayout.encode`
    documents, rounded once to float32 and clipped to ``bound`` in float32 (``state``: the scenarios'
    observed states, errors, drone positions, last outage probabilities, deliveries and powers;
    ``codec``: the layout's :data:`OBS_CODEC` record). The slot-dependent features (the reference windows,
    slot n / N) are the slot's row of the fixed path set's ``table`` when it has rows (clipped too with
    ``clip_table``), else computed here from each scenario's ``reference`` (B, K, T, 6) as
    :meth:`ObservationLayout.scaled_windows` does."""
    off = sc = codec[0]
    k, b32 = state[0].shape[1], np.float32(bound)
    for b in range(state[0].shape[0]):
        if table.shape[0] > 1:
            out[b, :] = table[slot[b]]
            if clip_table:
                for j in range(out.shape[1]):
                    out[b, j] = _clip32(out[b, j], b32)
        else:
            _encode_windows(out[b], reference[b], slot[b], off, sc, b32)
            out[b, k * off.agv_features + 2] = _clip32(np.float32(slot[b] / num_slots), b32)
        _encode_state(out[b], b, state, off, sc, b32)


@numba.njit(cache=True)
def _encode_windows(  # pragma: no cover - compiled
    row: np.ndarray, reference: np.ndarray, n: int, off: ObsCodec, sc: ObsCodec, b32: np.float32,
) -> None:
    """One scenario's reference windows at slot n: positions relative to slot n's, scaled."""
    for i in range(reference.shape[0]):
        col = i * off.agv_features + off.reference
        for w in range(off.window):
            for j in range(6):
                r = reference[i, n + w, j]
                if j < 2:
                    r = r - reference[i, n, j]
                row[col + 6 * w + j] = _clip32(np.float32(r * sc.reference_scale[j]), b32)


@numba.njit(cache=True)
def _encode_state(  # pragma: no cover - compiled
    row: np.ndarray, b: int, state: tuple[np.ndarray, ...], off: ObsCodec, sc: ObsCodec, b32: np.float32,
) -> None:
    """One scenario's state-dependent features: per AGV its state, error, position relative to the
    drone, last outage, delivery and power; then the drone's position."""
    x_obs, error_obs, drone, outage, delivered, power = state
    k = x_obs.shape[1]
    dx = (drone[b, 0] - sc.center[0]) * sc.inverse_half_extent[0]
    dy = (drone[b, 1] - sc.center[1]) * sc.inverse_half_extent[1]
    for i in range(k):
        base = i * off.agv_features
        for j in range(6):
            row[base + off.state + j] = _clip32(np.float32(x_obs[b, i, j] * sc.state_scale[j] - sc.state_shift[j]), b32)
            row[base + off.error + j] = _clip32(np.float32(error_obs[b, i, j] * sc.reference_scale[j]), b32)
        rel = base + off.relative_to_drone
        row[rel] = _clip32(np.float32((x_obs[b, i, 0] * sc.state_scale[0] - sc.state_shift[0]) - dx), b32)
        row[rel + 1] = _clip32(np.float32((x_obs[b, i, 1] * sc.state_scale[1] - sc.state_shift[1]) - dy), b32)
        row[base + off.outage_probability] = _clip32(np.float32(outage[b, i]), b32)
        row[base + off.delivered] = _clip32(np.float32(1.0 if delivered[b, i] else 0.0), b32)
        row[base + off.power] = _clip32(np.float32(power[b, i] * sc.inverse_budget), b32)
    g = k * off.agv_features
    row[g] = _clip32(np.float32(dx), b32)
    row[g + 1] = _clip32(np.float32(dy), b32)


@numba.njit(cache=True, inline="always")
def _clip32(v: np.float32, b32: np.float32) -> np.float32:  # pragma: no cover - compiled
    """A float32 feature clipped to [-b32, b32]."""
    if v > b32:
        return b32
    low: np.float32 = -b32
    if v < low:
        return low
    return v


class SlotTable(NamedTuple):
    """:meth:`ObservationLayout.slot_table`'s rows and their largest magnitude."""

    rows: np.ndarray
    peak: float


class ObservationLayout:
    """The observation vector of the central environments, and its inverse.

    Per AGV k (``agv_features = 17 + 6 (N_p + 1)`` floats):

    ==================  ==========================================================  ====================================
    slice               content                                                     scaling
    ==================  ==========================================================  ====================================
    0:2                 AGV position                                                (p - area center) / area half-extent
    2:4                 AGV velocity                                                / 5 m/s
    4:6                 previous acceleration u[n-1]                                / a_max
    6:12                tracking error x~ - x~_ref[n] (position, velocity, accel.)  / 10 m, / 5 m/s, / a_max
    12 : 12+6(N_p+1)    reference window i = 0..N_p: position relative to the       / 10 m, / 5 m/s, / a_max
                        reference position at slot n, velocity, acceleration
    next 2              AGV position relative to the drone                          / area half-extent
    next 1              outage probability of the last transmission                 probability
    next 1              last command delivered                                      0 or 1
    next 1              last power                                                  / P_max
    next 2 (N_p - 1)    under ``control.actuator="buffer"`` only: the buffer's      / Delta-a_max
                        increments in the order the AGV plays them on its next
                        slots without a packet, zeros once spent
                        (:func:`lawn_env.state.buffer_queue`)
    ==================  ==========================================================  ====================================

    Global features (3, at the end): drone position (2, like AGV positions), slot n / N.
    :meth:`decode` recovers the planner's state (the snapshot's arrays) from an observation.
    """

    #: The per-AGV features in order: name and names of its entries (the reference window's are
    #: repeated for i = 0..N_p, ``{i}`` replaced). Every offset and slice comes from this table.
    AGV_FEATURES = (
        ("state", ("x", "y", "vx", "vy", "ux_prev", "uy_prev")),
        ("error", ("ex", "ey", "evx", "evy", "eux", "euy")),
        ("reference", ("ref{i}_dx", "ref{i}_dy", "ref{i}_vx", "ref{i}_vy", "ref{i}_ax", "ref{i}_ay")),
        ("relative_to_drone", ("rel_drone_x", "rel_drone_y")),
        ("outage_probability", ("outage_prob",)),
        ("delivered", ("delivered",)),
        ("power", ("power_frac",)),
    )
    #: The buffered actuator's feature, after the others (its entries repeated for i = 1 .. N_p - 1).
    BUFFER_FEATURE = ("buffer", ("buffer{i}_ax", "buffer{i}_ay"))
    #: The global features after the K blocks: the drone's position, then slot n / N.
    GLOBAL_FEATURES = ("drone_x", "drone_y", "time_frac")
    global_features = len(GLOBAL_FEATURES)

    def __init__(self, config: ScenarioConfig):
        self.num_agvs = config.num_agvs
        self.horizon = config.control.horizon
        self.num_slots = config.num_slots
        x0, x1, y0, y1 = config.area_m
        self.center = np.array([(x0 + x1) / 2, (y0 + y1) / 2])
        self.half_extent = np.array([(x1 - x0) / 2, (y1 - y0) / 2])
        self.accel_max = config.control.accel_max_mps2
        self.power_budget_w = config.power_budget_w
        self.window = self.horizon + 1
        self.buffer_length = config.control.buffer_length
        self.increment_max = config.control.accel_increment_max_mps2
        #: The per-AGV features of this config: :attr:`AGV_FEATURES`, then the buffer's under the buffered actuator
        self.agv_feature_table = self.AGV_FEATURES + ((self.BUFFER_FEATURE,) if self.buffer_length else ())
        self.slices, start = {}, 0
        for name, entries in self.agv_feature_table:
            width = len(entries) * {"reference": self.window, "buffer": self.buffer_length}.get(name, 1)
            self.slices[name] = slice(start, start + width) if width > 1 else start
            start += width
        self.agv_features = start
        if self.buffer_length:  # the buffer's columns in the flat vector, AGV by AGV
            where = self.slices["buffer"]
            assert isinstance(where, slice)  # 2 (N_p - 1) >= 2 entries
            self._buffer_columns = (np.arange(self.num_agvs)[:, None] * start
                                    + np.arange(where.start, where.stop)[None, :]).reshape(-1)
        self.size = self.num_agvs * self.agv_features + self.global_features
        self._ref_scale = np.array([1 / POSITION_ERROR_SCALE_M] * 2 + [1 / VELOCITY_SCALE_MPS] * 2
                                   + [1 / self.accel_max] * 2)
        self._state_scale = np.concatenate([1 / self.half_extent, [1 / VELOCITY_SCALE_MPS] * 2,
                                            [1 / self.accel_max] * 2])
        self._state_shift = np.concatenate([self.center, np.zeros(4)])
        self._no_table = np.zeros((1, self.size), dtype=np.float32)
        codec = np.zeros(1, dtype=OBS_CODEC)  # filled by name: the table's order is free
        for name, where in self.slices.items():
            if name != "buffer":  # written by encode after the compiled rows
                codec[name] = where.start if isinstance(where, slice) else where
        codec["agv_features"], codec["window"] = self.agv_features, self.window
        codec["state_scale"], codec["state_shift"] = self._state_scale, self._state_shift * self._state_scale
        codec["reference_scale"], codec["center"] = self._ref_scale, self.center
        codec["inverse_half_extent"], codec["inverse_budget"] = 1.0 / self.half_extent, 1.0 / self.power_budget_w
        self._codec = codec

    def feature_names(self) -> list[str]:
        """Human-readable names of the per-AGV block, then of the globals."""
        names = []
        for name, entries in self.agv_feature_table:
            repeats = {"reference": range(self.window), "buffer": range(1, self.buffer_length + 1)}.get(name, [None])
            names += [e.format(i=i) for i in repeats for e in entries]
        return names + list(self.GLOBAL_FEATURES)

    #: :meth:`encode` precomputes a fixed path set's windows for the whole episode up to this
    #: size (float32 bytes), and gathers them per step beyond it.
    batch_window_table_bytes = 64 << 20

    def reference_windows(self, reference: np.ndarray, start: int = 0, stop: int | None = None) -> np.ndarray:
        """Scaled windows for slots ``start:stop`` (default: every slot): (K, slots, 6 (N_p+1)),
        positions relative to slot n's."""
        _, steps, _ = reference.shape
        last = steps - self.window + 1
        stop = last if stop is None else min(stop, last)
        idx = np.arange(start, stop)[:, None] + np.arange(self.window)[None, :]
        return self.scaled_windows(reference[:, idx])

    def scaled_windows(self, windows: np.ndarray) -> np.ndarray:
        """Raw reference windows (..., W, 6), slots n..n+N_p, as observation features
        (..., 6W): positions relative to slot n's, every entry scaled (a new array)."""
        win = windows.copy()
        win[..., POSITION] -= windows[..., 0:1, POSITION]
        win *= self._ref_scale
        features: np.ndarray = win.reshape((*win.shape[:-2], -1))
        return features

    def encode(self, sim: Simulation, bound: float | None = None, table: SlotTable | None = None) -> np.ndarray:
        """Observations of every scenario of a :class:`~lawn_env.core.Simulation` at its current
        slot: (B, size) float32, each feature computed in float64 and rounded once, then, with
        ``bound``, clipped to ``[-bound, bound]`` in float32 (what
        :meth:`RLInterface.observe <lawn_env.interface.RLInterface.observe>` does to an
        observation). With ``table``, the :meth:`slot_table` of the simulation's fixed path set, a
        step copies one table row per scenario and writes the state-dependent features over it;
        without it the compiled loop computes the reference windows from each scenario's reference
        as :meth:`scaled_windows` does (its oracle): the same observations."""
        st = sim.state
        out = np.empty((sim.num_envs, self.size), np.float32)
        rows, peak = (self._no_table, 0.0) if table is None else table
        state = (st.x_obs, st.error_obs, st.drone_position, st.last_outage_probability, st.last_delivered,
                 st.last_power_w)
        _encode_rows(out, rows, st.slot, state, st.reference, self._codec, self.num_slots,
                     np.inf if bound is None else bound,
                     bound is not None and peak > bound)  # the table's features clipped only where they exceed it
        if self.buffer_length:
            queue = buffer_queue(st.buffer, st.buffer_age).reshape(sim.num_envs, -1)  # AGV by AGV, as the columns
            feature = (queue * (1.0 / self.increment_max)).astype(np.float32)
            out[:, self._buffer_columns] = feature if bound is None else np.clip(feature, -bound, bound)
        return out

    def slot_table(self, shared: np.ndarray | None) -> SlotTable | None:
        """The features that depend only on the slot for the fixed path set ``shared`` (K, T, 6)
        (``SimParams.fixed_reference``), reference windows and slot n / N, as (slots, size)
        float32 rows (:meth:`encode` takes them); None for random paths or when over
        ``batch_window_table_bytes``."""
        if shared is None:
            return None
        slots = shared.shape[1] - self.window + 1
        if slots * self.size * 4 > self.batch_window_table_bytes:
            return None
        windows = self.reference_windows(shared)  # (K, slots, 6W)
        rows = np.zeros((slots, self.size), dtype=np.float32)
        k, f = self.num_agvs, self.agv_features
        rows[:, : k * f].reshape(slots, k, f)[..., self.slices["reference"]] = windows.transpose(1, 0, 2)
        rows[:, -1] = np.arange(slots) / self.num_slots
        return SlotTable(rows, float(np.abs(rows).max()))

    def agv_blocks(self, obs: np.ndarray) -> np.ndarray:
        """(K, agv_features) view of the per-AGV part."""
        return np.asarray(obs)[: self.num_agvs * self.agv_features].reshape(self.num_agvs, self.agv_features)

    def fleet_size_of(self, shape: tuple[int, ...]) -> int | None:
        """The K of an observation of ``shape`` at this layout's horizon (None when no K gives it)."""
        if len(shape) != 1 or shape[0] <= self.global_features or (shape[0] - self.global_features) % self.agv_features:
            return None
        return (shape[0] - self.global_features) // self.agv_features

    def check(self, obs: Any, hint: str = "") -> np.ndarray:
        """``obs`` as an array, after checking that it is one observation of this layout: every policy
        (planners through :meth:`decode`, learned policies before their network) rejects another shape
        with ``ValueError("observation has shape (10,); expected (335,)")``, then ``: hint`` if given."""
        array = np.asarray(obs)
        if array.shape != (self.size,):
            raise ValueError(f"observation has shape {array.shape}; expected ({self.size},)"
                             + (f": {hint}" if hint else ""))
        return array

    def decode(self, obs: np.ndarray) -> dict[str, Any]:
        """Planner state from an observation: ``x_aug`` (K, 6), ``reference`` (K, N_p+1, 6),
        ``drone_position`` (2,), ``slot``, ``last_power_w`` (K,), ``outage_probability`` (K,),
        ``buffer`` (K, N_p - 1, 2) under the buffered actuator (:attr:`lawn_env.core.Snapshot.buffer`), else None.

        Exact up to float32 rounding of the observation (about 1e-5 m in positions)."""
        obs = self.check(np.asarray(obs, dtype=np.float64))
        blocks = self.agv_blocks(obs)
        x_aug = blocks[:, self.slices["state"]] / self._state_scale + self._state_shift
        error = blocks[:, self.slices["error"]] / self._ref_scale
        win = blocks[:, self.slices["reference"]].reshape(self.num_agvs, self.window, 6) / self._ref_scale
        win[:, :, POSITION] += (x_aug[:, POSITION] - error[:, POSITION])[:, None, :]  # + reference position at slot n
        k = self.num_agvs * self.agv_features
        return {
            "x_aug": x_aug,
            "reference": win,
            "drone_position": obs[k : k + 2] * self.half_extent + self.center,
            "slot": round(float(obs[-1]) * self.num_slots),
            "last_power_w": blocks[:, self.slices["power"]] * self.power_budget_w,
            "outage_probability": blocks[:, self.slices["outage_probability"]],
            "buffer": (blocks[:, self.slices["buffer"]].reshape(self.num_agvs, self.buffer_length, 2)
                       * self.increment_max) if self.buffer_length else None,
        }
