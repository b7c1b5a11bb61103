"""Named scenario presets: plain :class:`~lawn_env.config.ScenarioConfig` instances.

``get(name)`` returns one; an unknown name raises ``ValueError`` listing the valid ones.
Register more with :func:`register` (a duplicate name raises).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from .config import ChannelConfig, DisturbanceConfig, DroneConfig, ReferenceConfig, ScenarioConfig

__all__ = ["PRESETS", "SUITE", "SUITE_V1", "SUITE_V2", "SUITE_VERSION", "LADDER", "Rung", "get", "names", "register",
           "resolve_config", "ConfigLike"]

PRESETS: dict[str, ScenarioConfig] = {}
#: What every ``config=`` argument takes: a ScenarioConfig, a dict of its fields, a preset name or None.
ConfigLike = ScenarioConfig | Mapping[str, Any] | str | None


def register(name: str, config: ScenarioConfig) -> None:
    if name in PRESETS:
        raise ValueError(f"preset {name!r} is already registered")
    if not isinstance(config, ScenarioConfig):
        raise TypeError(f"preset {name!r}: expected ScenarioConfig, got {type(config).__name__}")
    PRESETS[name] = config


def get(name: str) -> ScenarioConfig:
    try:
        return PRESETS[name]
    except KeyError:
        raise ValueError(f"unknown preset {name!r}; valid presets: {', '.join(names())}") from None


def names() -> list[str]:
    return sorted(PRESETS)


#: MODEL.md defaults: K = 4, R_th = 10 bit/s/Hz at 0 dBW, where outage is 1e-3 .. 0.7 (§8).
register("default", ScenarioConfig())
#: The paper's nominal point R_th = 1 bit/s/Hz: outage 1e-8 .. 1e-6 everywhere, so all policies
#: tie (MODEL.md §8). Kept as a reference point, not as a regime for comparisons.
register("paper-nominal", ScenarioConfig(channel=ChannelConfig(rate_threshold_bps_hz=1.0)))
#: Three AGVs (the paper's first tracking figure), otherwise the defaults.
register("k3", ScenarioConfig(num_agvs=3))
#: The stress variant of the reference paths (MODEL.md §1): the raw paper-like set, not slowed into
#: the AGVs' envelope, whose corners demand up to ~4 a_max; tracking error there is unavoidable.
register("stress-paths", ScenarioConfig(reference=ReferenceConfig(envelope_fraction=None)))
#: Sixteen AGVs on random paths at the default budget: the links lose about two commands in three
#: (suite v3's first task where links are poor).
register("k16", ScenarioConfig(num_agvs=16))
#: Thirty-two AGVs on random paths at the default budget: about four commands in five are lost (suite
#: v3's second task where links are poor; scaling studies and benchmarks).
register("k32", ScenarioConfig(num_agvs=32))
#: The default scenario with the disturbance mode on (MODEL.md §7: wind 2 m/s x, 2.5 m/s y with
#: gusts, actuator lag, process and measurement noise, commands every second slot).
register("disturbed", ScenarioConfig(disturbance=DisturbanceConfig(
    wind_mps=(2.0, 2.5), wind_gust_std_mps=1.0, actuator_lag_s=0.3, process_noise_position_m=0.05,
    process_noise_velocity_mps=0.05, measurement_noise_position_m=0.2, measurement_noise_velocity_mps=0.1,
    control_period_slots=2)))
#: Eight AGVs on the default area and budget: twice the links to share one power budget.
register("k8", ScenarioConfig(num_agvs=8))
#: The budget 2 dB below the default (-2 dBW): outage is high on far links, and where power goes matters more.
register("low-power", ScenarioConfig(power_budget_dbw=-2.0))
#: Commands of 128 channel uses instead of 1024: the finite-blocklength penalty raises the SNR threshold.
register("short-blocklength", ScenarioConfig(channel=ChannelConfig(blocklength=128)))
#: Imperfect CSI: a normalized estimation-error variance of 1e-4 (MODEL.md §2), planned for (the
#: CE-aware outage). It caps the effective SNR at 40 dB, 10 dB above the default threshold; at
#: 1e-3 the cap meets the threshold and every policy loses most commands.
register("imperfect-csi", ScenarioConfig(channel=ChannelConfig(ce_error_var=1e-4)))

# Suite v2's tasks decided throughout (docs/model-notes.md, "The task suite"): on the default task most of
# the cost falls in the first slots, the AGVs' recovery from their initial offsets while the drone
# flies in from the area's edge. A steady start removes that transient: the drone starts at the
# area's centre (above the paper paths' starts) and every AGV on its reference.
_STEADY_DRONE = DroneConfig(start_m=(100.0, 100.0))
_STEADY_REFERENCE = ReferenceConfig(initial_offset_std_m=0.0)
#: A steady start on the default scenario: the cost is the links' and the planner's, slot after slot.
register("steady", ScenarioConfig(drone=_STEADY_DRONE, reference=_STEADY_REFERENCE))
#: A steady start at -2 dBW: far links fail often, and where the power goes decides the cost.
register("steady-low-power", ScenarioConfig(power_budget_dbw=-2.0, drone=_STEADY_DRONE, reference=_STEADY_REFERENCE))
#: A steady start under the drone's wind and gusts and the AGVs' process noise (the ``disturbed``
#: preset's, without its actuator lag, measurement noise and halved command rate): a light
#: disturbance that keeps pushing the AGVs off their paths.
register("steady-gusty", ScenarioConfig(disturbance=DisturbanceConfig(
    wind_mps=(2.0, 2.5), wind_gust_std_mps=1.0, process_noise_position_m=0.05, process_noise_velocity_mps=0.05),
    drone=_STEADY_DRONE, reference=_STEADY_REFERENCE))
#: Eight AGVs on random paths over a 300 m square at +3 dBW, the drone starting at its centre and the
#: AGVs on their references: a fleet wider than one position serves well.
register("wide-k8", ScenarioConfig(num_agvs=8, area_m=(0.0, 300.0, 0.0, 300.0), power_budget_dbw=3.0,
                                   drone=DroneConfig(start_m=(150.0, 150.0)),
                                   reference=ReferenceConfig(initial_offset_std_m=0.0)))

# The learners' ladder (docs/LEARNED.md, "The ladder"): tasks below ``default`` that each leave one thing
# to learn, so that where learning from scratch stops can be read rung by rung.
_FIXED_DRONE = DroneConfig(start_m=(100.0, 100.0), max_speed_mps=0.01)
#: Only the power split is learned: a steady start with the drone held at the area's centre (its reach,
#: 5 mm a slot, is the least the config allows), so the drone's half of the action moves nothing.
register("learn-power", ScenarioConfig(drone=_FIXED_DRONE, reference=_STEADY_REFERENCE))
#: Only the AGVs' tracking is learned (on ``lawn/Joint-v1``): a steady start over links that lose nothing
#: (R_th = 1 bit/s/Hz, the ``paper-nominal`` threshold: outage below 1e-6 everywhere), so the power and
#: the drone change nothing and the cost is the increments'.
register("learn-tracking", ScenarioConfig(channel=ChannelConfig(rate_threshold_bps_hz=1.0), drone=_STEADY_DRONE,
                                          reference=_STEADY_REFERENCE))


@dataclass(frozen=True)
class Rung:
    """One rung of :data:`LADDER`: a preset, the env a learner acts on there and what is left to learn."""

    preset: str
    env_id: str
    learns: str


#: The ladder from the easiest rung to the scenario itself: one decision, then another, then two, then
#: the paper's task with its transient (``default`` on Comm), then with the AGVs' tracking too (on Joint).
LADDER: tuple[Rung, ...] = (
    Rung("learn-power", "lawn/Comm-v1", "the power split (the drone held, a steady start)"),
    Rung("learn-tracking", "lawn/Joint-v1", "the AGVs' increments (links that lose nothing, a steady start)"),
    Rung("steady", "lawn/Comm-v1", "the power split and the drone (a steady start)"),
    Rung("default", "lawn/Comm-v1", "the power split and the drone, from the start's transient"),
    Rung("default", "lawn/Joint-v1", "the power split, the drone and the increments, from the transient"),
)

#: The task suite of ``lawn benchmark --suite`` and the leaderboard (docs/LEADERBOARD.md): preset
#: names, default first. A change of its members or of their configs is a new SUITE_VERSION.
#: Version 3 adds to version 2's six tasks two where links are poor, 16 and 32 AGVs on the default
#: budget (65-82 % of the commands lost: where pricing the future under loss decides; docs/benchmark.md).
SUITE: tuple[str, ...] = ("default", "steady", "steady-low-power", "steady-gusty", "wide-k8", "disturbed", "k16", "k32")
SUITE_VERSION = 3
#: Suite version 2 (its tasks stay presets): the paper's scenario, the strong disturbance and four
#: tasks whose cost falls mostly after the transient.
SUITE_V2: tuple[str, ...] = ("default", "steady", "steady-low-power", "steady-gusty", "wide-k8", "disturbed")
#: Suite version 1 (its tasks stay presets): the paper's scenario and six variants of it, each
#: decided mostly by the transient of its first ten slots.
SUITE_V1: tuple[str, ...] = ("default", "k3", "k8", "low-power", "short-blocklength", "imperfect-csi", "disturbed")


def resolve_config(config: ConfigLike = None, **overrides: Any) -> ScenarioConfig:
    """A ScenarioConfig from a config object, a dict, a preset name or None (the defaults),
    with keyword overrides (top-level fields, or a section name mapped to a dict)."""
    if config is None:
        cfg = get("default")
    elif isinstance(config, ScenarioConfig):
        cfg = config
    elif isinstance(config, str):
        cfg = get(config)
    elif isinstance(config, Mapping):
        cfg = ScenarioConfig.from_dict(config)
    else:
        raise TypeError(
            f"config must be a ScenarioConfig, a dict, a preset name ({', '.join(names())}) or None; "
            f"got {type(config).__name__}"
        )
    return cfg.override(overrides) if overrides else cfg
