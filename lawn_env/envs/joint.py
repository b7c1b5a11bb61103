"""``lawn/Joint-v1``: the agent makes every decision of a slot."""

from __future__ import annotations

from .base import LawnEnv

__all__ = ["JointEnv"]


class JointEnv(LawnEnv):
    """
    ## Description

    A drone at fixed altitude serves K ground AGVs that track reference paths. Every slot
    (0.5 s) the agent chooses each AGV's acceleration increment, the split of the transmit power
    budget over the K links and the drone's move. Each command reaches its AGV only if the
    short-packet link is not in outage (Nakagami-m fading, finite blocklength, MODEL.md §2); a
    lost command leaves the AGV on its previous acceleration (with ``control.actuator="buffer"``:
    the AGV plays the next increment of the last plan it received, MODEL.md §3). This is problem
    P1 of the paper with the agent in place of the optimizer.

    ## Action Space

    ``Box(-1, 1, (3K + 2,), float32)``:

    | index      | meaning                           | scaling                                                     |
    |------------|-----------------------------------|-------------------------------------------------------------|
    | 0 .. 2K-1  | increment Delta-u of AGV k (x, y) | ``a * Delta-a_max`` m/s^2, saturated to ``abs(u) <= a_max`` |
    | 2K .. 3K-1 | power weight of link k            | ``w = (a+1)/2``, ``p = P_max w / max(1, sum w)``            |
    | 3K .. 3K+1 | drone velocity (x, y)             | ``a * V_max`` m/s, clipped to norm V_max, kept in area      |

    Under ``control.actuator="buffer"`` the box grows by ``2 K (N_p - 1)`` entries at the end: AGV by
    AGV, its planned increments for slots n+1 .. n+N_p-1 (x, y), ``a * Delta-a_max``, which its packet
    carries and it plays while no new packet arrives (the zero plan holds).

    Actions outside [-1, 1], NaN, or of the wrong size raise ``ValueError``. With
    ``interface="rl"`` (or ``RLInterface(action_scheme="anchored")``) the same box is measured
    from a safe anchor: increments are a residual ``a * Delta-a_max`` on the outage-aware MPC's
    first increment, power ``p_k ∝ prior_k exp(2 a_k)`` spends the budget (the prior: the stake prior,
    by what each command is worth, with ``interface="rl"``; ``d_k^2`` with ``power_anchor="distance"``,
    a bare ``RLInterface``'s default), the drone flies toward
    the AGVs' centroid ``+ a * 50 m`` (:mod:`lawn_env.interface`); the zero action is then a
    sound policy.

    ## Observation Space

    ``Box(-1e6, 1e6, (K (17 + 6 (N_p+1)) + 3,), float32)``, normalized to order one (features
    saturate at the bound; with ``interface="rl"`` at ±10): per AGV its position, velocity and
    previous acceleration, its tracking error, the reference window of N_p + 1 slots
    (relative position, velocity, acceleration), its position relative to the drone, the last
    outage probability, whether the last command arrived and the last power (under the buffered
    actuator also the ``2 (N_p - 1)`` increments its buffer would play next); then the drone
    position and the time. The table with scalings is :class:`lawn_env.spaces.ObservationLayout`;
    ``env.unwrapped.layout.decode(obs)`` inverts it.

    ## Rewards

    Minus the realized stage cost of the slot, summed over AGVs:
    ``e' Q1 e + Delta-u' Q2 Delta-u`` with ``e`` the augmented tracking error at slot n+1 and
    ``Delta-u`` the delivered increment (0 when lost). ``info["stage_cost"]`` is that cost and
    ``info["reward_tracking"]`` and ``info["reward_effort"]`` split it (negated), whatever the
    interface. With ``interface="rl"`` the reward is ``-min(cost, 100) / 10``, in [-10, 0].

    ## Starting State

    AGVs start at their reference start plus N(0, 3 m) per axis, with the reference velocity
    and zero previous acceleration; the drone starts at ``drone.start_m`` (0, 100) m. Reference
    paths are the paper-like set for K = 3, 4, otherwise drawn from the seed.

    ## Episode End

    No termination; truncation after ``num_slots`` (120) slots. The last step's
    ``info["episode_metrics"]`` holds the metrics of MODEL.md §6. With ``interface="rl"`` the
    episode terminates when an AGV is more than 25 m from its reference, and that step's reward
    includes the reward floor (-10) for every slot not played, so ending early never pays.

    ## Arguments

    ``gym.make("lawn/Joint-v1", config=None, render_mode=None, interface=None, **overrides)``:
    ``config`` is a :class:`~lawn_env.ScenarioConfig`, a dict or a preset name; overrides are
    top-level config fields or a section mapped to a dict, e.g. ``num_agvs=3,
    channel={"blocklength": 256}``. ``interface`` is None (the paper's benchmark), ``"rl"``,
    or an :class:`~lawn_env.RLInterface` / dict of its fields; ``lawn/JointRL-v1`` is this env
    with ``interface="rl"``. The interface's ``layout="entities"`` lays observations and actions
    out per AGV, padded to 64 rows with a mask (:mod:`lawn_env.entities`).

    ## Version History

    * v1: the native vector env (``gym.make_vec(..., vectorization_mode="vector_entry_point")``,
      :mod:`lawn_env.envs.vector`) draws every scenario's slot randomness from one generator (the
      env's, scenario 0's) and steps a mask of rows, so with N > 1 its episodes differ from v0's
      for the same seed (N = 1 equals this env bit for bit); observations saturate at ±1e6
      (``OBS_LIMIT``, the space's bound). Also, with single-env episodes bit for bit as v0's: reset
      and step infos share one flat schema (``lawn_env.envs.base.INFO_KEYS``;
      ``reward_tracking``/``reward_effort`` replace the nested ``reward_terms``), ``episode_metrics``
      summed slot by slot (within 1e-15 relative) and given on the step an episode ends; a made
      env's spec carries ``max_episode_steps`` (= ``num_slots``; the env truncates itself); every
      view runs one compiled simulation core; ``render()`` frames gain a colour bar of the links'
      outage probability (green to red) and the running control cost, at 512 x 448 pixels (480 x
      480 before); the interface's opt-in ``layout="entities"``; the opt-in buffered actuator
      (``control.actuator="buffer"``; the default hold's episodes bit for bit as before).
    * v0: initial version; the ``interface`` keyword (opt-in) and ``info["stage_cost"]`` added
      later. Still registered: ``lawn/Joint-v0`` builds this class without a native vector env
      (``gym.make_vec`` steps v0 scenarios side by side, each with its own generator).
    """
