"""Prediction-aware sampling MPC: candidate velocity commands rolled out 3.2 s and scored against the samples.

Each decision rolls out K candidate commands of the robot it drives (a holonomic robot: 24 headings x 3 speeds; a
differential drive: 9 turn rates x 3 forward speeds, standing and reversing; both: standing still and the previous
choice) through the robot's own model (``st_sim.sim.robot``: its limits, its kinematics), at two checks per 0.4 s
step, so it only plans what the robot can reach, and scores them against the
predicted samples of every pedestrian: the expected number of collisions, the clearance, the progress along
the geodesic cost-to-go of the walkability map, and the change of command. Paths that go deeper into a wall
than the ego already is are discarded. The predictor is whatever the env put in the observation; with
``use_predictions=False`` everybody is assumed to stand still.

The samples are weighted by their prior (``NavWorld.sample_prior``: how often each of a SingularTrajectory
checkpoint's ordered samples is the closest to the truth; equal weights for CVM-S and other unordered
samplers), so the chance of colliding with a pedestrian is the prior mass of its colliding samples rather
than their share. The chances add up over pedestrians (expected collisions, which keep growing where
1 - prod(1 - P) would saturate at 1 in a dense crowd), and a candidate whose expected collisions exceed
``risk_limit`` ranks behind every candidate within it. When all are above, the robot brakes (``safe_stop``):
a stopped robot is not at fault, and pedestrians who see it walk round it.

With ``track_modes`` the weights are per pedestrian (``modes.SampleBelief``): the prior, sharpened step by step by
how well each sample's first step matched where that pedestrian actually went.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from st_sim.apps.navigation.modes import SampleBelief
from st_sim.apps.navigation.pedestrians import Pedestrians, pedestrians_of
from st_sim.apps.navigation.world import NavWorld
from st_sim.sim.exact import dot, length, rounded_cos_sin
from st_sim.sim.robot import Motion, limited_command, substep

INFEASIBLE = 1e6  # cost of a candidate that goes into a wall [-]
RISK_PENALTY = 1e3  # cost of breaking the risk limit, plus this times the expected collisions [-]
ARRIVAL_SHARE = 0.8  # a rollout this deep inside the goal radius has arrived and stops there [-]


@dataclass(frozen=True)
class MpcConfig:
    """Tunables of the sampling MPC (costs are dimensionless; one unit = full-speed progress over the horizon)."""

    horizon_steps: int = 8
    """rollout length in 0.4 s steps (3.2 s)"""
    checks_per_step: int = 2
    """collision checks per step (positions interpolated linearly in between)"""
    headings: int = 24
    """holonomic robot: candidate directions, evenly spaced [-]"""
    turn_rates: int = 9
    """differential drive: candidate turn rates, evenly spaced within its limit (an odd count keeps 0) [-]"""
    speed_fractions: tuple[float, ...] = (1.0, 0.66, 0.33)
    """candidate speeds as shares of the speed limit [-]"""
    safety_margin_m: float = 0.15
    """a sample closer than contact + this counts as a collision [m]"""
    comfort_m: float = 0.6
    """clearance (beyond contact) below which the clearance cost grows [m]"""
    discount: float = 0.85
    """weight of a collision or intrusion one step later, relative to now [-]"""
    risk_horizon_steps: int = 6
    """steps of 0.4 s over which predicted samples are checked (the rollout still runs horizon_steps) [-]"""
    use_prior: bool = True
    """weight the samples by the world's sample prior (False: equally likely)"""
    top_samples: int = 20
    """with a prior, score only this many of the likeliest samples (weights renormalised) [-]"""
    risk_limit: float = 0.3
    """expected collisions above which a candidate ranks behind every candidate within it (inf: no limit) [-]"""
    safe_stop: bool = True
    """when every candidate is above the risk limit, brake (command zero) instead of taking the least risky"""
    track_modes: bool = True
    """with a prior: weigh each pedestrian's samples by how well they predicted its last step (``SampleBelief``)"""
    mode_sigma_m: float = 0.15
    """spread of the one-step likelihood of ``track_modes`` [m]"""
    mode_floor: float = 0.1
    """share of the prior mixed into every pedestrian's weights after each update [-]"""
    wall_margin_m: float = 0.08
    """least wall clearance beyond the world's ``wall_clearance_m`` a path may enter [m]"""
    wall_comfort_m: float = 0.3
    """wall clearance beyond the world's ``wall_clearance_m`` below which the wall cost grows [m]"""
    risk_weight: float = 6.0
    """cost of one expected collision [-]"""
    clearance_weight: float = 0.4
    """cost of one pedestrian's sample paths all at contact [-]"""
    progress_weight: float = 1.0
    """cost of coming no closer to the goal (full-speed progress saves this much) [-]"""
    smooth_weight: float = 0.15
    """cost of a command change of one speed limit [-]"""
    wall_weight: float = 0.5
    """cost of touching the wall-comfort band [-]"""


class MpcPlanner:
    """Sampling MPC over candidate commands of its robot, scored against the predicted futures; ``act`` returns the
    robot's own command (``drives_robot``).

    Args:
        world: the env's facts (limits, radii, map).
        use_predictions: False = the "none" predictor (pedestrians stand still).
        cfg: tunables.
    """

    def __init__(self, world: NavWorld, use_predictions: bool = True, cfg: MpcConfig | None = None):
        self.world, self.use_predictions, self.cfg = world, use_predictions, cfg or MpcConfig()
        prior = world.sample_prior
        self._belief = (SampleBelief(prior, self.cfg.mode_sigma_m, self.cfg.mode_floor)
                        if self.cfg.track_modes and self.cfg.use_prior and prior is not None else None)
        speeds = world.max_speed_mps * np.asarray(self.cfg.speed_fractions)
        robot = world.robot
        if robot.kind == "holonomic":
            angles = np.linspace(0.0, 2 * np.pi, self.cfg.headings, endpoint=False)
            unit = np.stack(rounded_cos_sin(angles), axis=1)  # the same on every CPU (libm's differ)
            commands = (speeds[:, None, None] * unit[None]).reshape(-1, 2)
        else:
            turns = np.linspace(-robot.max_yaw_rate_radps, robot.max_yaw_rate_radps, self.cfg.turn_rates)
            forward = np.r_[speeds, 0.0, -min(robot.max_reverse_mps, speeds.min())]
            commands = np.stack(np.broadcast_arrays(forward[:, None], turns[None]), axis=-1).reshape(-1, 2)
        self._commands = np.concatenate([commands, np.zeros((1, 2))])
        self._scale = np.abs(robot.command_high)  # one of each command component: its largest value
        steps = np.arange(1, self.cfg.horizon_steps * self.cfg.checks_per_step + 1) / self.cfg.checks_per_step
        self._check_steps = steps  # (J,) time of each check in steps
        self._weights = (self.cfg.discount ** (steps - 1 / self.cfg.checks_per_step)).astype(np.float32)  # (J,)
        self._weights[steps > self.cfg.risk_horizon_steps] = 0.0
        self.reset()

    def reset(self) -> None:
        """Forget the previous command and the pedestrians (call at every episode start)."""
        self._previous = np.zeros(2)
        if self._belief is not None:
            self._belief.reset()

    drives_robot = True
    """``act`` gives the robot's own command (a differential drive's (v, w)), not a velocity to be converted"""

    def act(self, obs: dict[str, np.ndarray]) -> np.ndarray:
        """The robot's command (2,): a holonomic robot's velocity [m/s], world frame; a differential drive's (v, w)."""
        commands, cost, risk, _ = self._scored(obs, self._commands)
        return self._choose(commands, cost, risk)

    def vet(self, obs: dict[str, np.ndarray], proposed: np.ndarray) -> tuple[np.ndarray, bool]:
        """(command (2,) [m/s], vetoed): the ``proposed`` command (2,) [m/s] of another planner when its rollout keeps
        within the risk limit and out of walls, else this planner's own choice (``act``'s, the proposal among the
        candidates); the previous command becomes the one returned."""
        proposal = np.asarray(proposed, np.float64).reshape(1, 2)
        commands, cost, risk, into_wall = self._scored(obs, np.concatenate([self._commands, proposal]))
        proposed_at = len(self._commands)  # its row: after the fixed candidates, before the previous command
        if risk[proposed_at] <= self.cfg.risk_limit and not into_wall[proposed_at]:
            self._previous = commands[proposed_at]
            return self._previous.astype(np.float32), False
        return self._choose(commands, cost, risk), True

    def _choose(self, commands: np.ndarray, cost: np.ndarray, risk: np.ndarray) -> np.ndarray:
        """(2,) float32 the cheapest command, or zero when even it breaks the risk limit and ``safe_stop`` holds; it
        becomes the previous command."""
        best = int(np.argmin(cost))
        stop = risk[best] > self.cfg.risk_limit and self.cfg.safe_stop
        self._previous = np.zeros(2) if stop else commands[best]
        return self._previous.astype(np.float32)

    def _scored(self, obs: dict[str, np.ndarray], candidates: np.ndarray
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(commands (K, 2) [m/s]: ``candidates`` then the previous command, their costs (K,), their expected
        collisions (K,), whether each path goes deeper into a wall than the ego is (K,) bool); updates the sample
        belief with ``obs``."""
        ego_xy, ego_v, goal, heading = (obs["ego"][i:i + 2].astype(np.float64) for i in (0, 2, 4, 6))
        robot = self.world.robot
        speed = float(length(ego_v)) if robot.kind == "holonomic" else float(dot(ego_v, heading))
        motion = Motion(ego_v[None], heading[None] / length(heading), np.array([speed]),
                        np.array([float(obs["ego"][8])]))
        peds = pedestrians_of(obs, self.cfg.horizon_steps, self.use_predictions)
        weights = None
        if self._belief is not None and self.use_predictions:
            weights = self._belief.update(obs)[obs["history_mask"][:, -1]]  # (P, S), rows of ``peds``
        commands = np.concatenate([candidates, self._previous[None]])
        path = self._rollout(ego_xy, motion, commands, goal)  # (K, J, 2)
        risk, crowding = self._risk_terms(path, ego_xy, peds, weights)
        walls = self._walls(path, ego_xy)
        cost = (self.cfg.risk_weight * risk + self.cfg.clearance_weight * crowding
                + self.cfg.progress_weight * self._progress(path, ego_xy, goal)
                + self.cfg.smooth_weight * self._smoothness(commands, motion.command_state(robot)[0])
                + walls
                + np.where(risk > self.cfg.risk_limit, RISK_PENALTY * (1.0 + risk), 0.0))
        return commands, cost, risk, walls >= INFEASIBLE

    # ---------------------------------------------------------------- rollout
    def _rollout(self, ego_xy: np.ndarray, motion: Motion, commands: np.ndarray, goal: np.ndarray) -> np.ndarray:
        """(K, J, 2) ego positions at the checks [m]: each command held, through the robot's model from its ``motion``
        now (one robot substep per check).

        A rollout that comes within ARRIVAL_SHARE of the goal radius stays there: the episode would end.
        """
        dt_s = self.world.step_s / self.cfg.checks_per_step
        k = len(commands)
        motion = Motion(*(np.repeat(part, k, axis=0) for part in motion))
        target = limited_command(self.world.robot, commands)
        position = np.broadcast_to(ego_xy, commands.shape).copy()
        arrived = np.zeros(k, bool)
        out = np.empty((k, len(self._check_steps), 2))
        for j in range(len(self._check_steps)):
            motion, velocity = substep(self.world.robot, motion, target, dt_s)
            position = np.where(arrived[:, None], position, position + velocity * dt_s)
            arrived |= np.linalg.norm(position - goal, axis=1) <= ARRIVAL_SHARE * self.world.goal_radius_m
            out[:, j] = position
        return out

    # ---------------------------------------------------------------- costs, each (K,)
    def _risk_terms(self, path: np.ndarray, ego_xy: np.ndarray, peds: Pedestrians,
                    weights: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Expected collisions (K,) and the clearance cost (K,), both summed over pedestrians.

        A sample collides if it comes within contact + safety margin of the path at a check; its intrusion
        is 1 at contact, falling to 0 at contact + comfort. Both are discounted by the check's time, and the
        largest over the checks counts. P(collide with p) is the sample weights' sum over p's colliding
        samples; risk = sum over p of P(collide with p).

        Args:
            weights: (P, S) per-pedestrian sample weights (``track_modes``); None: ``_sample_weights`` for all.
        """
        k = len(path)
        kept, shared = self._sample_weights(peds.futures_m.shape[1])
        per_ped = (np.broadcast_to(shared, (len(peds), len(kept))) if weights is None
                   else weights[:, kept] / weights[:, kept].sum(axis=1, keepdims=True)).astype(np.float32)
        futures = self._interpolated(peds.xy_m, peds.futures_m[:, kept])  # (P, S', J, 2)
        relevant = self._relevant(futures, ego_xy)
        futures, per_ped = futures[relevant], per_ped[relevant]
        if len(futures) == 0:
            return np.zeros(k), np.zeros(k)
        n_peds, n_samples = futures.shape[:2]
        ego = path.astype(np.float32)[:, None]  # (K, 1, J, 2)
        flat = futures.reshape(1, n_peds * n_samples, -1, 2)
        distance = np.sqrt((ego[..., 0] - flat[..., 0]) ** 2 + (ego[..., 1] - flat[..., 1]) ** 2)  # (K, P*S, J)
        reach_m = self.world.contact_m + self.cfg.comfort_m
        intrusion = np.clip((reach_m - distance) / self.cfg.comfort_m, 0.0, 1.0)
        hit_level = 1.0 - self.cfg.safety_margin_m / self.cfg.comfort_m
        hit = np.max((intrusion > hit_level) * self._weights, axis=-1).reshape(k, n_peds, n_samples)
        crowding = np.max(intrusion * self._weights, axis=-1).reshape(k, n_peds, n_samples)
        return np.einsum("kps,ps->k", hit, per_ped), np.einsum("kps,ps->k", crowding, per_ped)

    def _sample_weights(self, n_samples: int) -> tuple[np.ndarray, np.ndarray]:
        """Indices (S',) of the samples scored, the likeliest first, and their weights (S',) summing to 1."""
        prior = self.world.sample_prior
        if not self.cfg.use_prior or prior is None or len(prior) != n_samples:  # unordered: keep them all
            return np.arange(n_samples), np.full(n_samples, 1.0 / n_samples, np.float32)
        kept = np.argsort(-prior, kind="stable")[:self.cfg.top_samples]
        return kept, (prior[kept] / prior[kept].sum()).astype(np.float32)

    def _interpolated(self, xy_m: np.ndarray, futures_m: np.ndarray) -> np.ndarray:
        """(P, S, J, 2) float32 positions at the checks (linear between the predicted steps) from the positions
        now (P, 2) and the futures (P, S, H, 2) [m]."""
        now = np.broadcast_to(xy_m[:, None, None], (len(xy_m), futures_m.shape[1], 1, 2))
        track = np.concatenate([now, futures_m], axis=2)  # (P, S, H + 1, 2), step 0 = now
        low = np.floor(self._check_steps).astype(int)
        high = np.minimum(low + 1, track.shape[2] - 1)
        frac = (self._check_steps - low)[:, None]
        return (track[:, :, low] * (1 - frac) + track[:, :, high] * frac).astype(np.float32)

    def _relevant(self, futures: np.ndarray, ego_xy: np.ndarray) -> np.ndarray:
        """(P,) bool: some sample comes within the ego's reach at some check (others cannot matter)."""
        reach_m = (self.world.max_speed_mps * self.world.step_s * self._check_steps
                   + self.world.contact_m + self.cfg.comfort_m)  # (J,)
        distance = np.linalg.norm(futures - ego_xy.astype(np.float32), axis=-1)  # (P, S, J)
        return (distance < reach_m).any(axis=(1, 2))

    def _progress(self, path: np.ndarray, ego_xy: np.ndarray, goal: np.ndarray) -> np.ndarray:
        """Change of geodesic cost-to-go over the horizon, in units of full-speed travel (-1 = best)."""
        terrain = self.world.terrain
        body_m = self.world.wall_clearance_m + self.cfg.wall_margin_m
        now = terrain.cost_to_go(ego_xy, goal, body_m)
        end = terrain.cost_to_go(path[:, -1], goal, body_m)
        return (end - now) / (self.world.max_speed_mps * self.world.step_s * self.cfg.horizon_steps)

    def _smoothness(self, commands: np.ndarray, now: np.ndarray) -> np.ndarray:
        """Squared command change from where the robot is now (``now`` (2,), in the command's terms) and from the
        previous command, each component in units of its largest value (the speed limit, the turn-rate limit)."""
        return (np.sum(((commands - now) / self._scale) ** 2, axis=1)
                + np.sum(((commands - self._previous) / self._scale) ** 2, axis=1))

    def _walls(self, path: np.ndarray, ego_xy: np.ndarray) -> np.ndarray:
        """Wall-comfort cost, or INFEASIBLE for a path that goes deeper into a wall than the ego is now."""
        terrain, radius = self.world.terrain, self.world.wall_clearance_m
        clearance = terrain.clearance_at(path)  # (K, J)
        allowed = min(radius + self.cfg.wall_margin_m, float(terrain.clearance_at(ego_xy)))
        band = np.clip((radius + self.cfg.wall_comfort_m - clearance) / self.cfg.wall_comfort_m, 0.0, 1.0)
        return np.where(clearance.min(axis=1) < allowed - 1e-6, INFEASIBLE, self.cfg.wall_weight * band.max(axis=1))
