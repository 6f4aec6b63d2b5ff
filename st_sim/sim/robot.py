"""The robot every scenario drives: its kind, its limits, and how a command becomes its motion over a 0.4 s step.

Two kinds share one model (``RobotSpec``):

- ``holonomic``: the command is a velocity (vx, vy) [m/s], world frame. The velocity moves toward it (scaled down to
  ``max_speed_mps``) by at most ``max_accel_mps2`` per second, or ``max_brake_mps2`` when the change opposes the
  motion. The heading is the direction it last moved in; it has no turning dynamics of its own.
- ``diff-drive`` (a unicycle, two driven wheels): the command is (v, w), forward speed [m/s] and turn rate [rad/s]
  (counter-clockwise positive). The forward speed moves toward v (within [-``max_reverse_mps``, ``max_speed_mps``])
  by at most ``max_accel_mps2`` per second (``max_brake_mps2`` when slowing down), the turn rate toward w (within
  +-``max_yaw_rate_radps``) by at most ``max_yaw_accel_radps2``; the body moves on the arc that speed and turn rate
  trace, so it never moves sideways.

A step is integrated in substeps (2 of 0.2 s in every world: replays and simulated crowds alike). Speed and turn rate
change at the start of each substep and hold within it. Optional, off by default: action latency (the robot acts on
the command given ``latency_steps`` steps before) and actuation noise (each command component scaled by 1 + a normal
draw of ``actuation_noise``), drawn from the robot's own generator so that noise never changes the crowd.

Arithmetic: IEEE-exact operations and ``st_sim.sim.exact``'s functions only, so that a robot moves the same to the last
bit on every CPU (``tests/test_cpu_dispatch.py`` drives both kinds under emulated CPUs, commands beyond the limits
included).
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np

from replays.constants import STEP_S
from st_sim.sim.checks import named
from st_sim.sim.exact import atan2, cap_speed, cos_sin, dot, length

ROBOT_KINDS: tuple[str, ...] = ("holonomic", "diff-drive")
SUBSTEPS = 2  # substeps of a 0.4 s step in which the robot's speeds change (0.2 s each)
HEADING_SPEED_MPS = 1e-3  # a holonomic robot slower than this keeps its heading [m/s]
CLIP_TOLERANCE = 1e-6  # a command farther than this from what the robot reached was clipped [m/s or rad/s]
SMALL_ANGLE_RAD = 1e-4  # below this half-turn per substep the arc's chord factor is its series [rad]


class RobotSpecError(ValueError):
    """A robot kind or limit that cannot be used; the message names the field."""


@dataclass(frozen=True)
class RobotSpec:
    """The robot's kind and limits (metres, seconds, radians); the same in every scenario of a run.

    Defaults (``ROBOTS``; sources in docs/robot.md): both kinds share the speed and the linear limits, so that the
    kinds differ in their kinematics only: 1.5 m/s (the suite's speed since its first version; robot_sf's bases allow
    2.0, SocNavBench's 1.2), 2.0 m/s^2 to speed up and to brake (the simulated crowds' robot since env v1; robot_sf's
    differential drive 1.0, SEAN's Jackal 5.0). The differential drive turns at up to 2.0 rad/s (robot_sf 1.0,
    SocNavBench 1.1, a Kobuki base 3.1, SEAN's Jackal 8) with 4.0 rad/s^2 of turn acceleration (robot_sf 1.0, SEAN's
    Jackal 25) and reverses at up to 0.5 m/s (SocNavBench: never).
    """

    kind: str = "holonomic"
    """"holonomic" (command (vx, vy) [m/s]) or "diff-drive" (command (v, w): forward speed [m/s], turn rate [rad/s])"""
    max_speed_mps: float = 1.5
    """fastest speed (holonomic: in any direction; diff-drive: forward) [m/s], (0, 10]"""
    max_reverse_mps: float = 0.0
    """diff-drive: fastest backward speed [m/s], [0, max_speed_mps] (holonomic: 0, unused)"""
    max_accel_mps2: float = 2.0
    """largest change of velocity per second while speeding up or turning [m/s^2], (0, 100]"""
    max_brake_mps2: float = 2.0
    """largest change of velocity per second while slowing down [m/s^2], [max_accel_mps2, 100]"""
    max_yaw_rate_radps: float = math.inf
    """diff-drive: fastest turn [rad/s], (0, 20] (holonomic: inf, its heading follows its motion)"""
    max_yaw_accel_radps2: float = math.inf
    """diff-drive: largest change of turn rate per second [rad/s^2], (0, 1000] (holonomic: inf)"""
    latency_steps: int = 0
    """steps between a command and the robot acting on it (0: at once), [0, 10]"""
    actuation_noise: float = 0.0
    """standard deviation of the relative error of each command component the robot acts on (0: none), [0, 1]"""

    def __post_init__(self) -> None:
        if not isinstance(self.kind, str) or self.kind not in ROBOT_KINDS:
            raise RobotSpecError(f"RobotSpec.kind = {self.kind!r}: expected one of {', '.join(ROBOT_KINDS)}")
        holonomic = self.kind == "holonomic"
        ranges = {"max_speed_mps": (0.0, 10.0, True), "max_accel_mps2": (0.0, 100.0, True),
                  "max_brake_mps2": (0.0, 100.0, True), "actuation_noise": (0.0, 1.0, False),
                  "max_reverse_mps": (0.0, 10.0, False)}
        if not holonomic:
            ranges |= {"max_yaw_rate_radps": (0.0, 20.0, True), "max_yaw_accel_radps2": (0.0, 1000.0, True)}
        for name, (low, high, open_low) in ranges.items():
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int | float | np.floating | np.integer) or not (
                    low < value <= high if open_low else low <= value <= high):
                side = "(" if open_low else "["
                raise RobotSpecError(f"RobotSpec.{name} = {value!r}: expected a number in {side}{low:g}, {high:g}]")
        latency = self.latency_steps
        if isinstance(latency, bool) or not isinstance(latency, int | np.integer) or not 0 <= latency <= 10:
            raise RobotSpecError(f"RobotSpec.latency_steps = {latency!r}: expected an int in [0, 10]")
        if self.max_brake_mps2 < self.max_accel_mps2:
            raise RobotSpecError(f"RobotSpec.max_brake_mps2 = {self.max_brake_mps2!r}: braking may not be weaker than "
                                 f"speeding up (max_accel_mps2 = {self.max_accel_mps2!r})")
        if self.max_reverse_mps > self.max_speed_mps:
            raise RobotSpecError(f"RobotSpec.max_reverse_mps = {self.max_reverse_mps!r}: above max_speed_mps "
                                 f"= {self.max_speed_mps!r}")
        if holonomic and (self.max_reverse_mps != 0.0 or self.max_yaw_rate_radps != math.inf
                          or self.max_yaw_accel_radps2 != math.inf):
            raise RobotSpecError("RobotSpec: a holonomic robot has no reverse or turn limits (max_reverse_mps 0, "
                                 "max_yaw_rate_radps and max_yaw_accel_radps2 inf); use kind='diff-drive'")

    @property
    def command_low(self) -> np.ndarray:
        """(2,) the least command of each component (the action space's low)."""
        if self.kind == "holonomic":
            return np.full(2, -self.max_speed_mps)
        return np.array([-self.max_reverse_mps, -self.max_yaw_rate_radps])

    @property
    def command_high(self) -> np.ndarray:
        """(2,) the largest command of each component (the action space's high)."""
        if self.kind == "holonomic":
            return np.full(2, self.max_speed_mps)
        return np.array([self.max_speed_mps, self.max_yaw_rate_radps])

    @property
    def command_names(self) -> tuple[str, str]:
        """What the two command components are, with their units."""
        return ("vx_mps", "vy_mps") if self.kind == "holonomic" else ("v_mps", "w_radps")


ROBOTS: dict[str, RobotSpec] = {
    "holonomic": RobotSpec(),
    "diff-drive": RobotSpec(kind="diff-drive", max_reverse_mps=0.5, max_yaw_rate_radps=2.0, max_yaw_accel_radps2=4.0),
}
"""the documented default of each kind, by name (``robot_spec``)"""


def robot_spec(robot: str | RobotSpec | None) -> RobotSpec:
    """The spec ``robot`` names: a ``RobotSpec`` as it is, a kind's name (``ROBOTS``), None for the holonomic default.

    Raises:
        RobotSpecError: anything else, naming the choices.
    """
    return named(robot, ROBOTS, RobotSpec, "holonomic", "robot", RobotSpecError)


class Motion(NamedTuple):
    """The motion state of K robots of one spec (arrays over the leading axis).

    Attributes:
        velocity_mps: (K, 2) world frame [m/s].  heading: (K, 2) unit vector the body faces.
        speed_mps: (K,) diff-drive: forward speed (negative: reversing); holonomic: the speed [m/s].
        yaw_rate_radps: (K,) turn rate [rad/s] (holonomic: 0).
    """

    velocity_mps: np.ndarray
    heading: np.ndarray
    speed_mps: np.ndarray
    yaw_rate_radps: np.ndarray

    @classmethod
    def standing(cls, heading: np.ndarray) -> Motion:
        """K robots at rest facing ``heading`` (K, 2) (normalised; a zero vector faces +x)."""
        heading = np.asarray(heading, np.float64).reshape(-1, 2)
        norm = length(heading)
        unit = np.where((norm > 0)[:, None], heading / np.where(norm > 0, norm, 1.0)[:, None], [1.0, 0.0])
        zeros = np.zeros(len(unit))
        return cls(np.zeros_like(unit), unit, zeros, zeros.copy())

    def command_state(self, spec: RobotSpec) -> np.ndarray:
        """(K, 2) where the robot is in the command's terms: its velocity (holonomic) or (speed, turn rate)."""
        if spec.kind == "holonomic":
            return self.velocity_mps
        return np.stack([self.speed_mps, self.yaw_rate_radps], axis=1)


def limited_command(spec: RobotSpec, command: np.ndarray) -> np.ndarray:
    """(K, 2) commands within the spec's speed limits: a holonomic velocity scaled down (direction kept) to
    ``max_speed_mps``, a diff-drive (v, w) clipped to its ranges. Commands must be finite."""
    command = np.asarray(command, np.float64).reshape(-1, 2)
    if spec.kind == "diff-drive":
        return np.clip(command, spec.command_low, spec.command_high)
    largest = np.abs(command).max(axis=1)
    over = largest > spec.max_speed_mps
    scale = spec.max_speed_mps / np.where(over, largest, 1.0)  # no overflow: the largest component becomes the limit
    command = np.where(over[:, None], command * scale[:, None], command)
    return cap_speed(command, np.full(len(command), spec.max_speed_mps))


def substep(spec: RobotSpec, motion: Motion, command: np.ndarray, dt_s: float) -> tuple[Motion, np.ndarray]:
    """One substep of ``dt_s`` seconds of K robots toward their ``limited_command`` commands (K, 2).

    Returns:
        the motion after it, and (K, 2) the displacement over it divided by ``dt_s`` [m/s] (a diff-drive robot's
        chord of its arc: along its heading at the substep's middle).
    """
    if spec.kind == "holonomic":
        change = command - motion.velocity_mps
        limit = np.where(dot(change, motion.velocity_mps) < 0, spec.max_brake_mps2, spec.max_accel_mps2) * dt_s
        velocity = motion.velocity_mps + cap_speed(change, limit)
        speed = length(velocity)
        moving = speed > HEADING_SPEED_MPS
        heading = np.where(moving[:, None], velocity / np.where(moving, speed, 1.0)[:, None], motion.heading)
        return Motion(velocity, heading, speed, np.zeros_like(speed)), velocity
    speed_change = command[:, 0] - motion.speed_mps
    limit = np.where(speed_change * motion.speed_mps < 0, spec.max_brake_mps2, spec.max_accel_mps2) * dt_s
    speed = motion.speed_mps + np.clip(speed_change, -limit, limit)
    turn_limit = spec.max_yaw_accel_radps2 * dt_s
    yaw_rate = motion.yaw_rate_radps + np.clip(command[:, 1] - motion.yaw_rate_radps, -turn_limit, turn_limit)
    half = 0.5 * yaw_rate * dt_s  # half the turn of the substep [rad]
    cos_half, sin_half = cos_sin(half)
    middle = rotated(motion.heading, cos_half, sin_half)
    small = np.abs(half) < SMALL_ANGLE_RAD
    chord = np.where(small, 1.0 - half * half / 6.0, sin_half / np.where(small, 1.0, half))  # chord / arc length
    heading = rotated(middle, cos_half, sin_half)
    heading = heading / length(heading)[:, None]  # no drift of the unit length over an episode
    chord_velocity = (speed * chord)[:, None] * middle
    return Motion(speed[:, None] * heading, heading, speed, yaw_rate), chord_velocity


def rotated(unit: np.ndarray, cos: np.ndarray, sin: np.ndarray) -> np.ndarray:
    """(K, 2) the vectors ``unit`` (K, 2) turned counter-clockwise by the angles whose cosines and sines are given."""
    return np.stack([unit[:, 0] * cos - unit[:, 1] * sin, unit[:, 0] * sin + unit[:, 1] * cos], axis=1)


def command_toward(spec: RobotSpec, heading: np.ndarray, velocity_mps: np.ndarray) -> np.ndarray:
    """(K, 2) commands that drive K robots facing ``heading`` (K, 2) toward the velocities (K, 2) [m/s] a planner
    wishes: the velocity itself for a holonomic robot; for a diff-drive robot, the turn rate that would face it within
    one 0.4 s step (within the limit) and the wished speed times the cosine of the angle still to turn (0 beyond a
    quarter turn: it turns on the spot first). A planner that does not know its robot drives through this."""
    velocity_mps = np.asarray(velocity_mps, np.float64).reshape(-1, 2)
    if spec.kind == "holonomic":
        return velocity_mps.copy()
    heading = np.asarray(heading, np.float64).reshape(-1, 2)
    along = dot(heading, velocity_mps)
    across = heading[:, 0] * velocity_mps[:, 1] - heading[:, 1] * velocity_mps[:, 0]
    angle = atan2(across, along)
    speed = length(velocity_mps)
    forward = np.maximum(along, 0.0)  # = speed * cos(angle), 0 beyond a quarter turn
    turn = np.where(speed > HEADING_SPEED_MPS, angle / STEP_S, 0.0)
    return np.stack([np.minimum(forward, spec.max_speed_mps),
                     np.clip(turn, -spec.max_yaw_rate_radps, spec.max_yaw_rate_radps)], axis=1)


@dataclass(frozen=True)
class Actuation:
    """What became of one step's command (robot_sf's feasibility report).

    Attributes (pairs of floats, so that two reports compare with ``==``):
        command: as given.  applied: what the robot acted on (after latency and noise).
        reached: where the robot's speeds ended the step, in the command's terms.
        gap: |command - reached| per component [m/s, or m/s and rad/s].
        clipped: the limits kept the robot from ``applied`` (some component of ``applied - reached`` above
            ``CLIP_TOLERANCE``).
    """

    command: tuple[float, float]
    applied: tuple[float, float]
    reached: tuple[float, float]
    gap: tuple[float, float]
    clipped: bool


class Robot:
    """One robot under a ``RobotSpec``: its motion, its pending commands (latency) and its noise generator.

    A holonomic robot steps through ``holonomic_substep``, the same arithmetic as ``substep`` on plain floats (the
    same bits, without an array's overhead on a single robot).

    Args:
        spec: kind and limits.  heading: (2,) the direction it faces at rest (normalised).
        rng: the robot's own generator, needed only with ``actuation_noise`` (``RobotSpecError`` without it).
    """

    def __init__(self, spec: RobotSpec, heading: Any = (1.0, 0.0), rng: np.random.Generator | None = None):
        if spec.actuation_noise > 0 and rng is None:
            raise RobotSpecError("RobotSpec.actuation_noise > 0 needs the robot's own generator (rng)")
        self.spec, self.rng = spec, rng
        self.motion = Motion.standing(np.asarray(heading, np.float64))
        self.pending: deque[np.ndarray] = deque([np.zeros(2)] * spec.latency_steps)
        self.last: Actuation | None = None
        """the last step's report (None before the first)"""

    @property
    def velocity_mps(self) -> np.ndarray:
        """(2,) world frame [m/s]."""
        return self.motion.velocity_mps[0].copy()

    @property
    def heading(self) -> np.ndarray:
        """(2,) unit vector the body faces."""
        return self.motion.heading[0].copy()

    @property
    def yaw_rate_radps(self) -> float:
        """Turn rate [rad/s] (holonomic: 0)."""
        return float(self.motion.yaw_rate_radps[0])

    def drive(self, command: np.ndarray | None, substeps: int = SUBSTEPS) -> np.ndarray:
        """Act on a finite (2,) ``command`` (None: stop) for one 0.4 s step; (substeps, 2) the velocity of each
        substep's straight move [m/s] (a world moves the body by these). ``last`` reports the step."""
        given = np.zeros(2) if command is None else np.asarray(command, np.float64).reshape(2)
        self.pending.append(given)
        applied = self.pending.popleft()
        if self.spec.actuation_noise > 0:
            applied = applied * (1.0 + self.spec.actuation_noise * self.rng.standard_normal(2))
        if self.spec.kind == "holonomic":
            moves = self._drive_holonomic(*holonomic_target(self.spec, float(applied[0]), float(applied[1])),
                                          substeps)
        else:
            target = limited_command(self.spec, applied)
            moves = np.empty((substeps, 2))
            for k in range(substeps):
                self.motion, chord = substep(self.spec, self.motion, target, STEP_S / substeps)
                moves[k] = chord[0]
        reached = self.motion.command_state(self.spec)[0]
        self.last = Actuation(pair(given), pair(applied), pair(reached), pair(np.abs(given - reached)),
                              bool((np.abs(applied - reached) > CLIP_TOLERANCE).any()))
        return moves

    def _drive_holonomic(self, tx: float, ty: float, substeps: int) -> np.ndarray:
        """``substep`` of a holonomic robot toward the target velocity (tx, ty) [m/s], on floats."""
        spec, dt_s = self.spec, STEP_S / substeps
        (vx, vy), (hx, hy) = self.motion.velocity_mps[0].tolist(), self.motion.heading[0].tolist()
        moves = []
        for _ in range(substeps):
            vx, vy, hx, hy = holonomic_substep(vx, vy, hx, hy, tx, ty, spec.max_accel_mps2 * dt_s,
                                               spec.max_brake_mps2 * dt_s)
            moves.append((vx, vy))
        speed = math.sqrt(vx * vx + vy * vy)
        self.motion = Motion(np.array([[vx, vy]]), np.array([[hx, hy]]), np.array([speed]), np.zeros(1))
        return np.array(moves)


def pair(values: np.ndarray) -> tuple[float, float]:
    """(2,) values as a pair of floats."""
    return float(values[0]), float(values[1])


def holonomic_target(spec: RobotSpec, x: float, y: float) -> tuple[float, float]:
    """``limited_command`` of one holonomic command (x, y) [m/s], on floats (the same bits)."""
    largest = max(abs(x), abs(y))
    if largest > spec.max_speed_mps:
        scale = spec.max_speed_mps / largest
        x, y = x * scale, y * scale
    speed = math.sqrt(x * x + y * y)
    scale = min(1.0, spec.max_speed_mps / max(speed, 1e-9))
    return x * scale, y * scale


def holonomic_substep(vx: float, vy: float, hx: float, hy: float, tx: float, ty: float, accel: float,
                      brake: float) -> tuple[float, float, float, float]:
    """One holonomic substep on floats: the velocity (vx, vy) moves toward the target (tx, ty) [m/s] by at most
    ``accel`` (``brake`` when the change opposes the motion) [m/s]; the heading (hx, hy) follows the motion. The same
    operations, in the same order, as ``substep`` (``exact.cap_speed``)."""
    cx, cy = tx - vx, ty - vy
    limit = brake if cx * vx + cy * vy < 0 else accel
    change = math.sqrt(cx * cx + cy * cy)
    scale = min(1.0, limit / max(change, 1e-9))
    vx, vy = vx + cx * scale, vy + cy * scale
    speed = math.sqrt(vx * vx + vy * vy)
    if speed > HEADING_SPEED_MPS:
        hx, hy = vx / speed, vy / speed
    return vx, vy, hx, hy
