"""The episode's running sums and the metrics of MODEL.md §6 read from them.

* :class:`Totals`: the running sums of B scenarios by name, over the packed array
  ``SimState.totals`` (B, 5 + 3K) the slot kernel advances (one array crosses into compiled code
  as cheaply as one argument); the kernel writes its columns through the offsets named here, which
  numba compiles in as constants (so this file stamps the kernels' cache, :mod:`lawn_env.kernel_cache`).
* :class:`EpisodeMetrics`: MODEL.md §6's metrics of one scenario's episode, by name;
  :func:`episode_metrics` reads them from the sums of the slots each scenario has run. The envs'
  ``info["episode_metrics"]`` is the record as a dict (:meth:`EpisodeMetrics.as_dict`), as
  Gymnasium's info is.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

#: One scenario's metrics as the envs' info carries them: counts, costs and rates by name, the per-AGV
#: ones as lists (:meth:`EpisodeMetrics.as_dict`).
Metrics = dict[str, float | int | list[float]]

__all__ = ["Metrics", "EpisodeMetrics", "Totals",
           "TOTALS", "TRACKING", "EFFORT", "OUTAGE_P", "PATH", "PER_AGV", "DIVERGENCE_DISTANCE_M",
           "episode_metrics"]

#: The columns of the running sums (B, 5 + 3K) in order: the tracking and effort costs, the predicted
#: outage probabilities, the drone's path length, then per AGV the squared position errors, the lost
#: commands and the powers (a block of K columns each), and last the largest squared position error of
#: any AGV so far (a running maximum). The outage and power sums count the slots that send a command
#: only: on the others nothing is transmitted (MODEL.md §7).
TOTALS = ("tracking", "effort", "outage_p", "path", "sq_error", "outages", "power", "max_sq_error")
#: The scalar sums' columns, and the first column of the per-AGV blocks (block j starts at PER_AGV + j K).
TRACKING, EFFORT, OUTAGE_P, PATH, PER_AGV = 0, 1, 2, 3, 4
#: An episode has diverged when some AGV's position error passed this many metres (the RL interface's
#: termination distance; MODEL.md §6): ``episode_metrics``'s ``diverged``.
DIVERGENCE_DISTANCE_M = 25.0


class Totals:
    """The running sums (:data:`TOTALS`) of B scenarios by name: views of the packed array ``packed``
    (B, 5 + 3K), or of one scenario's (5 + 3K,) without the B axis."""

    __slots__ = ("num_agvs", "packed")

    def __init__(self, packed: np.ndarray):
        self.packed = packed
        self.num_agvs = (packed.shape[-1] - PER_AGV - 1) // 3

    @staticmethod
    def zeros(num: int, num_agvs: int) -> np.ndarray:
        """The packed sums of ``num`` scenarios at the start of their episodes."""
        return np.zeros((num, PER_AGV + 1 + 3 * num_agvs))

    def _block(self, j: int) -> np.ndarray:
        k = self.num_agvs
        return self.packed[..., PER_AGV + j * k : PER_AGV + (j + 1) * k]

    @property
    def tracking(self) -> np.ndarray:
        """The tracking cost so far, sum of e' Q1 e."""
        return self.packed[..., TRACKING]

    @property
    def effort(self) -> np.ndarray:
        """The effort cost so far, sum of du' Q2 du."""
        return self.packed[..., EFFORT]

    @property
    def control_cost(self) -> np.ndarray:
        """Tracking + effort."""
        total: np.ndarray = self.packed[..., TRACKING] + self.packed[..., EFFORT]
        return total

    @property
    def outage_p(self) -> np.ndarray:
        """The predicted outage probabilities summed over the AGVs and the command slots."""
        return self.packed[..., OUTAGE_P]

    @property
    def path(self) -> np.ndarray:
        """The drone's path length, m."""
        return self.packed[..., PATH]

    @property
    def sq_error(self) -> np.ndarray:
        """Per AGV, its squared position errors summed over the slots (..., K)."""
        return self._block(0)

    @property
    def outages(self) -> np.ndarray:
        """Per AGV, its lost commands (..., K)."""
        return self._block(1)

    @property
    def power(self) -> np.ndarray:
        """Per AGV, the powers radiated to it summed over the command slots, W (..., K)."""
        return self._block(2)

    @property
    def max_sq_error(self) -> np.ndarray:
        """The largest squared position error of any AGV at any slot so far."""
        return self.packed[..., PER_AGV + 3 * self.num_agvs]


@dataclass(frozen=True)
class EpisodeMetrics:
    """MODEL.md §6's metrics of one scenario's episode over the slots it has run (the decision time is
    the caller's): ``control_cost`` (tracking + effort) and its parts, the RMSE of the position errors
    (over the AGVs and per AGV), the outage rates over the commands sent (with commands every P slots,
    the slots n with n % P == 0; realized, predicted, per AGV), the power radiated per link averaged
    over every slot (0 W on a slot without a command), the drone's path length, the largest position
    error of any AGV at any slot and ``diverged`` (1 when it passed :data:`DIVERGENCE_DISTANCE_M`)."""

    slots: int
    control_cost: float
    tracking_cost: float
    effort_cost: float
    rmse_m: float
    rmse_per_agv_m: list[float]
    outage_rate: float
    outage_rate_predicted: float
    outage_rate_per_agv: list[float]
    mean_power_w: list[float]
    drone_path_length_m: float
    max_tracking_error_m: float
    diverged: int

    def as_dict(self) -> Metrics:
        """The metrics by name, in field order (the envs' ``info["episode_metrics"]``)."""
        return {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}

    @classmethod
    def from_dict(cls, metrics: Mapping[str, object]) -> EpisodeMetrics:
        """The record of an env's ``info["episode_metrics"]``; a ``ValueError`` naming the keys that are
        missing or not metrics."""
        names = [f.name for f in dataclasses.fields(cls)]
        missing, unknown = [n for n in names if n not in metrics], [k for k in metrics if k not in names]
        if missing or unknown:
            raise ValueError(f"episode metrics {sorted(metrics)}: missing {missing}, unknown {unknown}; the "
                             f"metrics are {', '.join(names)}")
        return cls(**metrics)  # type: ignore[arg-type]  # every name checked above; the values are the env's


def episode_metrics(totals: Totals, slots: np.ndarray, command_period: int) -> list[EpisodeMetrics]:
    """:class:`EpisodeMetrics` over the ``slots`` (B,) each of B scenarios has run in its episode, from
    its running sums (``command_period``: commands every P slots), one per scenario."""
    n, k, period = slots, totals.num_agvs, command_period
    if np.any(n == 0):
        raise RuntimeError("no slot has been simulated yet")
    sent = (n + period - 1) // period  # the command slots 0, P, 2P, ... among slots 0..n-1 (step's rule)
    nk, per = sent * k, sent[:, None]
    sq_error, outages, power = totals.sq_error, totals.outages, totals.power
    largest = np.sqrt(totals.max_sq_error)
    columns = zip(n.tolist(), totals.control_cost.tolist(), totals.tracking.tolist(), totals.effort.tolist(),
                  np.sqrt(sq_error.sum(axis=1) / (n * k)).tolist(), np.sqrt(sq_error / n[:, None]).tolist(),
                  (outages.sum(axis=1) / nk).tolist(), (totals.outage_p / nk).tolist(), (outages / per).tolist(),
                  (power / n[:, None]).tolist(), totals.path.tolist(), largest.tolist(),
                  (largest > DIVERGENCE_DISTANCE_M).astype(int).tolist(), strict=True)
    return [EpisodeMetrics(slots=s, control_cost=c, tracking_cost=tc, effort_cost=ec, rmse_m=r, rmse_per_agv_m=ra,
                           outage_rate=o, outage_rate_predicted=op, outage_rate_per_agv=oa, mean_power_w=pw,
                           drone_path_length_m=pl, max_tracking_error_m=mx, diverged=d)
            for s, c, tc, ec, r, ra, o, op, oa, pw, pl, mx, d in columns]
