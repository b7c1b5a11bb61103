"""Scenario configuration: every quantity of MODEL.md §1–2 with its default and unit.

The configuration is a tree of frozen dataclasses validated on construction (pydantic
dataclasses; a bad value raises :class:`~lawn_env.errors.ConfigError`, a ``ValueError`` naming
each bad field by its dotted path, the value given and what is allowed). Building from a dict
rejects unknown keys by name (:class:`~lawn_env.errors.UnknownConfigKeyError`). Fields marked
*(decided)* are choices MODEL.md makes where the paper is silent; they are ordinary, overridable
fields.

Units are part of every field name (``_m``, ``_s``, ``_mps``, ``_db``, ``_dbw``, ``_dbm``,
``_bps_hz``); the functions of :mod:`lawn_env.channel` take linear values, and the derived
linear quantities are exposed as properties (``power_budget_w``, ``alpha0``, ``noise_power_w``).
"""

from __future__ import annotations

import dataclasses
import typing
from collections.abc import Mapping
from typing import Annotated, Any, Literal

import numpy as np
from pydantic import ConfigDict, Field, model_validator
from pydantic.dataclasses import dataclass

from .errors import ConfigError, UnknownConfigKeyError, raises_config_errors

__all__ = [
    "ConfigError",
    "UnknownConfigKeyError",
    "ChannelConfig",
    "ControlConfig",
    "DroneConfig",
    "ReferenceConfig",
    "DisturbanceConfig",
    "ScenarioConfig",
    "REFERENCE_FAMILIES",
]

_PYDANTIC = ConfigDict(extra="forbid", allow_inf_nan=False, validate_assignment=True, use_attribute_docstrings=True)

PositiveFloat = Annotated[float, Field(gt=0)]
PositiveInt = Annotated[int, Field(ge=1, strict=True)]

#: The bits of one planned increment of one axis in a packet of the buffered actuator (MODEL.md §3).
INCREMENT_BITS = 16


def check_payload(config: ScenarioConfig) -> None:
    """Raise ``ValueError`` when the buffered actuator's sequence (2 N_p increments of
    :data:`INCREMENT_BITS` bits) does not fit the message of R_th l bits the link's outage is computed
    for (``control.actuator="buffer"``; MODEL.md §3)."""
    ch, horizon = config.channel, config.control.horizon
    need, room = 2 * horizon * INCREMENT_BITS, ch.rate_threshold_bps_hz * ch.blocklength
    if need > room:
        raise ValueError(
            f"control.actuator='buffer' with control.horizon={horizon}: a packet carries the planned sequence, "
            f"2 x {horizon} increments of {INCREMENT_BITS} bits = {need} bits, but the message is "
            f"channel.rate_threshold_bps_hz x channel.blocklength = {ch.rate_threshold_bps_hz:g} x {ch.blocklength} = "
            f"{room:g} bits; shorten the horizon, raise the rate or the blocklength, or use control.actuator='hold'")


#: Reference-path families of :mod:`lawn_env.references` (MODEL.md §1).
REFERENCE_FAMILIES = ("lemniscate", "rounded_rectangle", "sinusoid", "spline")


@raises_config_errors("channel.")
@dataclass(frozen=True, config=_PYDANTIC)
class ChannelConfig:
    """Drone-to-AGV short-packet link (MODEL.md §2)."""

    nakagami_m: PositiveInt = 2
    """Nakagami shape m (a positive integer, paper)."""
    alpha0_db: Annotated[float, Field(ge=-200, le=0)] = -50.0
    """Reference channel gain at 1 m, dB, in [-200, 0] (a passive channel does not amplify) (paper)."""
    noise_power_dbm: Annotated[float, Field(ge=-250, le=100)] = -100.0
    """Receiver noise power sigma^2, dBm, in [-250, 100] (paper: -100)."""
    bandwidth_hz: PositiveFloat = 1e6
    """Sub-channel bandwidth B, Hz; rates are in bit/s/Hz, B only converts them to bit/s (paper)."""
    bler: Annotated[float, Field(gt=0, lt=0.5)] = 1e-6
    """Block error rate epsilon, in (0, 0.5) (paper: 1e-6): at 0.5 and above Q^-1(epsilon) <= 0 and the
    FBL "penalty" would raise the rate above Shannon's."""
    blocklength: PositiveInt = 1024
    """Blocklength l, channel uses (paper)."""
    rate_threshold_bps_hz: Annotated[float, Field(gt=0, le=100)] = 10.0
    """Rate threshold R_th, bit/s/Hz *(decided, MODEL.md §8)*: 10 sits in the regime where outage
    matters (1e-3 .. 0.7 at 0 dBW). It is not the paper's stated parameter: the paper's typeset figures
    use 1 Mbit/s over 1 MHz (R_th = 1, the ``paper-nominal`` preset, where outage is 1e-8 .. 1e-5 and
    all policies tie); a parameter table with 10 is commented out of its source."""
    infinite_blocklength: bool = False
    """Use the IBL rate log2(1 + SNR) instead of the FBL rate (the limit l -> inf)."""
    paper_rate_form: bool = False
    """Drop the log2(e) factor of the dispersion term, as the paper prints the FBL rate (MODEL.md §2;
    a units slip there). The paper's closed-form threshold (its generalized Lambert-W series for
    kappa*) is derived from the rate as printed, so it is the threshold of this form, not of the
    default one."""
    ce_error_var: Annotated[float, Field(ge=0, lt=1)] = 0.0
    """Normalized channel-estimation error variance rho, in [0, 1) (MODEL.md §2)."""
    ce_aware_planning: bool = True
    """Planners inside the package (the Comm-v1 MPC, experts) use rho in their outage model;
    False makes them CSI-unaware (they plan with rho = 0) *(decided)*."""
    perfect_links: bool = False
    """Every command is delivered: the SNR threshold G_th is 0, so the outage probability is 0 on
    every link for the simulator and the planners alike. Not a channel but a reference: the
    ``limit:perfect-links`` headroom row of the benchmark (docs/benchmark.md) *(decided)*."""

    @property
    def alpha0(self) -> float:
        """Reference channel gain, linear."""
        gain: float = 10.0 ** (self.alpha0_db / 10.0)
        return gain

    @property
    def noise_power_w(self) -> float:
        """Noise power, W."""
        power: float = 10.0 ** ((self.noise_power_dbm - 30.0) / 10.0)
        return power


@raises_config_errors("drone.")
@dataclass(frozen=True, config=_PYDANTIC)
class DroneConfig:
    """Drone kinematics (MODEL.md §1)."""

    altitude_m: Annotated[float, Field(gt=0, le=10_000)] = 50.0
    """Fixed flight altitude H, m, in (0, 10 km] (a low-altitude network) (paper)."""
    start_m: tuple[float, float] = (0.0, 100.0)
    """Initial horizontal position q[1], m (paper)."""
    max_speed_mps: Annotated[float, Field(ge=0.01, le=300)] = 15.0
    """Maximum horizontal speed V_max, m/s, in [0.01, 300] (a drone's reach V_max Δτ must be
    resolvable in metres by the planners' drone grids) *(decided)*."""


@raises_config_errors("control.")
@dataclass(frozen=True, config=_PYDANTIC)
class ControlConfig:
    """Outage-aware MPC of each AGV (MODEL.md §3)."""

    horizon: Annotated[int, Field(ge=1, le=100, strict=True)] = 10
    """Prediction horizon N_p, slots, in [1, 100] (paper: 10; the MPC's QPs are dense in 2 N_p
    variables and ``rg-mpc`` tabulates them per plan: at 100 a plan already takes about a second)."""
    q1_diag: tuple[float, float, float, float, float, float] = (1.0,) * 6
    """Diagonal of the state-error weight Q1 (6 entries in [0, 1e6]; the two position weights > 0: the
    terminal weight Q3 solves a DARE that needs the position error in the cost) (paper: I6)."""
    q2_diag: tuple[float, float] = (1.0, 1.0)
    """Diagonal of the increment weight Q2 (2 entries in [1e-6, 1e6], Q2 positive definite) (paper: I2)."""
    accel_max_mps2: Annotated[float, Field(ge=0.01, le=100)] = 2.0
    """Acceleration bound a_max per axis, m/s^2, in [0.01, 100] (10 g; observations are scaled by
    it) *(decided)*."""
    accel_increment_max_mps2: Annotated[float, Field(ge=0.001)] = 1.0
    """Increment bound per axis per slot, m/s^2, at least 0.001 and at most 2 a_max (actions are
    scaled by it) *(decided)*."""
    law: Literal["paper", "delivery", "delivery-certainty-equivalent"] = "paper"
    """The increments the AGVs of ``lawn/Comm-v1`` apply (the MPC the environment solves for them;
    ``lawn/Joint-v1``'s actions carry the increments; the RL interface's MPC anchor plans by it too):
    ``"paper"``, the paper's QP P3 at the link's planned success probability psi (its
    expected-trajectory cost scales the command with psi); ``"delivery"``, the command planned as if it
    arrives with the later ones priced under loss, ``dv-mpc``'s loss-aware tail at the fleet's expected
    delivery (MODEL.md §4, "Planning under loss"; :class:`lawn_env.tail.DeliveryLaw`);
    ``"delivery-certainty-equivalent"``, the QP at psi = 1, every later command priced as delivered
    (MODEL.md §4, "Planning under delivery": the delivery law before the loss-aware tail, which
    diverges where links lose most commands) *(decided)*."""

    actuator: Literal["hold", "buffer"] = "hold"
    """What an AGV applies in a slot whose packet does not arrive (MODEL.md §3): ``"hold"``, a zero
    increment (it keeps u[n-1]; the paper's actuator); ``"buffer"``, the next element of the last
    increment sequence it received (packetized predictive control: every packet carries the sender's
    whole planned sequence of N_p increments; an AGV whose buffer is spent holds). The sequence is
    2 N_p numbers of 16 bits, which the message of R_th l bits must hold *(decided extension)*."""

    @property
    def buffer_length(self) -> int:
        """The planned increments a packet carries after the command, which a buffered actuator plays
        on loss: N_p - 1 under ``actuator="buffer"``, 0 under the hold."""
        return self.horizon - 1 if self.actuator == "buffer" else 0

    @model_validator(mode="after")
    def _check_weights(self) -> ControlConfig:
        if any(w < 0 or w > 1e6 for w in self.q1_diag) or min(self.q1_diag[:2]) <= 0:
            raise ValueError(f"control.q1_diag={self.q1_diag}: entries must lie in [0, 1e6] and the two position "
                             "weights be > 0 (the DARE of the terminal weight needs the position error in the cost; "
                             "weights beyond 1e6 make it numerically singular)")
        if any(w < 1e-6 or w > 1e6 for w in self.q2_diag):
            raise ValueError(f"control.q2_diag={self.q2_diag}: every entry must lie in [1e-6, 1e6] (Q2 positive "
                             "definite: smaller weights leave the MPC's QPs numerically singular, larger ones the "
                             "DARE)")
        return self


@raises_config_errors("reference.")
@dataclass(frozen=True, config=_PYDANTIC)
class ReferenceConfig:
    """Reference paths of the AGVs (MODEL.md §1, decided)."""

    path_set: Literal["auto", "paper", "random"] = "auto"
    """"paper": the fixed paper-like set (K = 3 or 4 only); "random": paths drawn at reset from
    ``families`` with the episode seed; "auto": "paper" when K is 3 or 4, otherwise "random"."""
    families: tuple[str, ...] = REFERENCE_FAMILIES
    """Families the random set draws from."""
    initial_offset_std_m: Annotated[float, Field(ge=0)] = 3.0
    """Std of the initial AGV position offset from the reference start, per axis, m *(decided)*."""
    envelope_fraction: Annotated[float, Field(gt=0, le=1)] | None = 0.9
    """Feasibility *(decided, MODEL.md §1)*: every path is slowed down (uniform time scaling) until
    ``|a_ref| <= f a_max`` and ``|a_ref[n+1] - a_ref[n]| <= f Delta-a_max`` per axis at every slot. None
    keeps the raw paths: the stress variant (preset ``stress-paths``), where the paper-like set
    demands up to ~4 a_max at its corners."""

    @model_validator(mode="after")
    def _check_families(self) -> ReferenceConfig:
        if not self.families:
            raise ValueError("reference.families=(): give at least one of " + ", ".join(REFERENCE_FAMILIES))
        unknown = [f for f in self.families if f not in REFERENCE_FAMILIES]
        if unknown:
            raise ValueError(
                f"reference.families: unknown {unknown}; allowed: {', '.join(REFERENCE_FAMILIES)}"
            )
        return self


NonNegative = Annotated[float, Field(ge=0)]


@raises_config_errors("disturbance.")
@dataclass(frozen=True, config=_PYDANTIC)
class DisturbanceConfig:
    """The disturbance mode that stands in for the paper's AirSim validation (MODEL.md §7, decided).

    All off by default; the ``disturbed`` preset switches them on with the values below in
    brackets. Planners are not told about them: they plan with the nominal model.
    """

    wind_mps: tuple[float, float] = (0.0, 0.0)
    """Mean wind drifting the drone, m/s [(2.0, 2.5), the paper's AirSim setting]."""
    wind_gust_std_mps: NonNegative = 0.0
    """Std of the per-slot gust added to the wind, m/s per axis [1.0]."""
    actuator_lag_s: NonNegative = 0.0
    """Time constant of a first-order lag between the commanded and the applied AGV acceleration, s [0.3]."""
    process_noise_position_m: Annotated[float, Field(ge=0, le=1e3)] = 0.0
    """Std of the per-slot AGV position noise, m per axis [0.05]."""
    process_noise_velocity_mps: Annotated[float, Field(ge=0, le=1e3)] = 0.0
    """Std of the per-slot AGV velocity noise, m/s per axis [0.05]."""
    measurement_noise_position_m: Annotated[float, Field(ge=0, le=1e3)] = 0.0
    """Std of the noise on the AGV positions the policies observe, m per axis [0.2]."""
    measurement_noise_velocity_mps: Annotated[float, Field(ge=0, le=1e3)] = 0.0
    """Std of the noise on the AGV velocities the policies observe, m/s per axis [0.1]."""
    control_period_slots: PositiveInt = 1
    """Commands are sent every this many slots (a reduced control rate); in between nothing is
    transmitted and the AGVs keep their last acceleration (under ``control.actuator="buffer"`` they
    play their buffers, whose plans from a period-aware planner hold in between) [2]."""
    period_aware_planning: bool = True
    """The planners know ``control_period_slots`` *(decided, MODEL.md §7)*: the MPC (experts,
    baselines, ``lawn/Comm-v1``'s controller) and the PID/LQR rollouts plan with move blocking, an
    increment only at the slots where a command goes out, held in between. False is the ablation
    where they plan as if they commanded every slot."""

    @property
    def active(self) -> bool:
        return (any(self.wind_mps) or self.wind_gust_std_mps > 0 or self.actuator_lag_s > 0
                or self.process_noise_position_m > 0 or self.process_noise_velocity_mps > 0
                or self.measurement_noise_position_m > 0 or self.measurement_noise_velocity_mps > 0
                or self.control_period_slots > 1)


@raises_config_errors()
@dataclass(frozen=True, config=_PYDANTIC)
class ScenarioConfig:
    """One scenario: K AGVs tracking reference paths, one drone serving them over FBL links.

    Build with keywords (``ScenarioConfig(num_agvs=3)``), from a dict
    (:meth:`from_dict`, rejects unknown keys), from a preset (:func:`lawn_env.presets.get`), or
    derive one with :meth:`override` (dotted keys such as ``"channel.blocklength"``).
    """

    num_agvs: Annotated[int, Field(ge=1, le=256, strict=True)] = 4
    """Number of AGVs K, in [1, 256] (paper: 3, 4; the planners' cost grows with K)."""
    num_slots: Annotated[int, Field(ge=1, le=100_000, strict=True)] = 120
    """Episode length N in slots, in [1, 100000] (paper: 120 slots = 60 s; the reference table of
    an episode is precomputed)."""
    slot_s: Annotated[float, Field(ge=1e-3, le=10)] = 0.5
    """Slot duration Delta-tau, s, in [1 ms, 10 s] (paper: 0.5; one command per slot, a discrete
    double integrator between commands; the terminal weight's Riccati equation degenerates as the
    slot goes to zero)."""
    area_m: tuple[float, float, float, float] = (0.0, 200.0, 0.0, 200.0)
    """Area D as (x_min, x_max, y_min, y_max), m (paper: 200 m square); each side in [1 m, 100 km],
    coordinates within ±1,000 km."""
    power_budget_dbw: Annotated[float, Field(ge=-100, le=60)] = 0.0
    """Total transmit power budget P_max, dBW (paper: 0 dBW)."""
    channel: ChannelConfig = dataclasses.field(default_factory=ChannelConfig)
    drone: DroneConfig = dataclasses.field(default_factory=DroneConfig)
    control: ControlConfig = dataclasses.field(default_factory=ControlConfig)
    reference: ReferenceConfig = dataclasses.field(default_factory=ReferenceConfig)
    disturbance: DisturbanceConfig = dataclasses.field(default_factory=DisturbanceConfig)

    @model_validator(mode="after")
    def _check_scenario(self) -> ScenarioConfig:
        x0, x1, y0, y1 = self.area_m
        if not (x1 > x0 and y1 > y0):
            raise ValueError(f"area_m={self.area_m}: need x_min < x_max and y_min < y_max")
        if not (1.0 <= x1 - x0 <= 1e5 and 1.0 <= y1 - y0 <= 1e5) or max(map(abs, self.area_m)) > 1e6:
            raise ValueError(f"area_m={self.area_m}: each side must lie in [1 m, 100 km] and every coordinate "
                             "within ±1e6 m (float32 observations resolve positions to a decimetre there)")
        qx, qy = self.drone.start_m
        if not (x0 <= qx <= x1 and y0 <= qy <= y1):
            raise ValueError(f"drone.start_m={self.drone.start_m} must lie inside area_m={self.area_m}")
        if self.num_agvs * self.num_slots > 2_000_000:
            raise ValueError(f"num_agvs={self.num_agvs} x num_slots={self.num_slots} exceeds 2,000,000: an episode's "
                             "reference table is precomputed (K x N <= 2e6 keeps it under 100 MB)")
        if self.reference.path_set == "paper" and self.num_agvs not in (3, 4):
            raise ValueError(
                f"reference.path_set='paper' is defined for num_agvs 3 or 4, got num_agvs={self.num_agvs}; "
                "use path_set='random' or 'auto'"
            )
        from .rate import snr_threshold  # it must exist for these rate, blocklength and BLER

        ch = self.channel
        if not ch.infinite_blocklength:
            try:
                snr_threshold(ch.rate_threshold_bps_hz, ch.blocklength, ch.bler, ch.paper_rate_form)
            except (ValueError, RuntimeError, OverflowError, ZeroDivisionError) as exc:
                raise ValueError(
                    f"channel.rate_threshold_bps_hz={ch.rate_threshold_bps_hz}, channel.blocklength={ch.blocklength}, "
                    f"channel.bler={ch.bler}: no SNR threshold reaches this rate at this blocklength ({exc})"
                ) from None
        if self.control.actuator == "buffer":
            check_payload(self)
        from .dynamics import PredictionModel  # the MPC's terminal weight Q3 must exist for these weights

        ctl = self.control
        try:
            PredictionModel.from_config(self)  # cached per (slot, horizon, Q1, Q2)
        except (ValueError, ArithmeticError, np.linalg.LinAlgError) as exc:
            raise ValueError(
                f"control.q1_diag={ctl.q1_diag}, control.q2_diag={ctl.q2_diag} (slot_s={self.slot_s}): the terminal "
                f"weight Q3, the solution of the discrete Riccati equation, is not finite for these weights ({exc}); "
                "keep the weights within a few orders of magnitude of each other"
            ) from None
        if self.control.accel_increment_max_mps2 > 2 * self.control.accel_max_mps2:
            raise ValueError(
                f"control.accel_increment_max_mps2={self.control.accel_increment_max_mps2} exceeds "
                f"2 * accel_max_mps2={2 * self.control.accel_max_mps2}: the bound could never be active"
            )
        return self

    # ----------------------------------------------------------------- derived quantities
    @property
    def power_budget_w(self) -> float:
        """P_max, W."""
        power: float = 10.0 ** (self.power_budget_dbw / 10.0)
        return power

    @property
    def drone_reach_m(self) -> float:
        """V_max Δτ: how far the drone can move in one slot, m."""
        return self.drone.max_speed_mps * self.slot_s

    @property
    def duration_s(self) -> float:
        return self.num_slots * self.slot_s

    @property
    def uses_paper_paths(self) -> bool:
        mode = self.reference.path_set
        return mode == "paper" or (mode == "auto" and self.num_agvs in (3, 4))

    # ----------------------------------------------------------------- (de)serialization
    def to_dict(self) -> dict[str, Any]:
        """Plain nested dict (JSON-serializable) that :meth:`from_dict` accepts back."""
        plain: dict[str, Any] = _to_plain(dataclasses.asdict(self))
        return plain

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> ScenarioConfig:
        """Build from a nested dict; unknown keys raise :class:`UnknownConfigKeyError` naming them."""
        if not isinstance(data, Mapping):
            raise TypeError(f"config must be a mapping, got {type(data).__name__}")
        _check_keys(cls, data, "")
        return cls(**dict(data))

    def override(self, overrides: Mapping[str, Any] | None = None, **kwargs: Any) -> ScenarioConfig:
        """Return a copy with fields replaced.

        Keys are top-level field names, dotted paths (``"channel.blocklength"``), or a section
        name mapped to a dict of that section's fields (``channel={"blocklength": 256}``).
        Unknown keys raise ``ValueError``; the result is validated again.
        """
        merged = dict(overrides or {})
        merged.update(kwargs)
        tree = self.to_dict()
        for key, value in merged.items():
            parts = key.split(".")
            node = tree
            for depth, part in enumerate(parts):
                if not isinstance(node, dict) or part not in node:
                    where = ".".join(parts[: depth + 1])
                    raise UnknownConfigKeyError(f"unknown config key {where!r} (unexpected keyword argument "
                                                f"{where!r}); valid keys: {_valid_keys(self)}", [where])
                if depth == len(parts) - 1:
                    if isinstance(node[part], dict) and isinstance(value, Mapping):
                        for sub in value:
                            if sub not in node[part]:
                                raise UnknownConfigKeyError(
                                    f"unknown config key '{key}.{sub}'; valid keys: {_valid_keys(self)}",
                                    [f"{key}.{sub}"])
                        node[part] = {**node[part], **dict(value)}
                    else:
                        node[part] = value
                else:
                    node = node[part]
        return type(self).from_dict(tree)


def _to_plain(value: Any) -> Any:
    if isinstance(value, dict):
        return {k: _to_plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_to_plain(v) for v in value]
    return value


def _check_keys(cls: type[Any], data: Mapping[str, Any], prefix: str) -> None:
    """Unknown keys of a (nested) config dict, named with their dotted path."""
    fields = {f.name for f in dataclasses.fields(cls)}
    hints = typing.get_type_hints(cls)
    for key, value in data.items():
        if key not in fields:
            raise UnknownConfigKeyError(f"unknown config key {prefix + str(key)!r}; valid keys: "
                                        f"{_valid_keys(ScenarioConfig())}", [prefix + str(key)])
        sub = hints.get(key)
        if isinstance(value, Mapping) and isinstance(sub, type) and dataclasses.is_dataclass(sub):
            _check_keys(sub, value, f"{prefix}{key}.")


def _valid_keys(cfg: ScenarioConfig) -> str:
    keys: list[str] = []

    def walk(tree: dict[str, Any], prefix: str) -> None:
        for k, v in tree.items():
            if isinstance(v, dict):
                walk(v, f"{prefix}{k}.")
            else:
                keys.append(prefix + k)

    walk(cfg.to_dict(), "")
    return ", ".join(keys)
