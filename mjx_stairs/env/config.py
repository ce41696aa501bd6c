"""The stair env's settings: frozen dataclasses, saved whole in every policy file."""

from __future__ import annotations

import dataclasses
from typing import Any, Literal, Sequence

from mjx_stairs.config import ConfigError, apply_overrides, from_dict, to_dict
from mjx_stairs.env import curriculum as cur
from mjx_stairs.env import rewards as rw
from mjx_stairs.sim import robot as rb


def _require(prefix: str, checks: list[tuple[str, Any, bool, str]]) -> None:
    """ConfigError naming the first of ``checks`` (name, value, ok, what it must be) not ok."""
    for name, value, ok, need in checks:
        if not ok:
            raise ConfigError(f"config key '{prefix}.{name}': must be {need}, got {value}")


@dataclasses.dataclass(frozen=True)
class NoiseConfig:
    """Uniform observation noise half-widths per group (actor stream only)."""

    enabled: bool = True
    lin_vel: float = 0.1
    ang_vel: float = 0.2
    gravity: float = 0.05
    joint_pos: float = 0.01
    joint_vel: float = 1.5
    height: float = 0.1
    # The height map as an elevation map gets it wrong (issue 24; all 0: off). A missing cell
    # reads +clip, what a robot-side runner writes for a cell without data (tools/contract.py).
    height_offset: float = 0.0  # m, uniform +- per robot and episode, added to every cell
    height_missing: float = 0.0  # chance per step that any one cell is missing
    height_missing_body: float = 0.0  # the same for the cells under the trunk (occluded)
    height_missing_edge: float = 0.0  # the same for the cells beside a step edge
    # Scale the three chances by a per-robot, per-episode draw in [0, 1], so complete maps are
    # as usual as holey ones. Without it a policy trained with holes under the trunk never sees
    # a complete map there, and stops ~0.55 m short of the goal when it gets one (the 2026-11-24
    # generalist going up: 12-19 % at test level 1, 94-100 % with the training's holes back).
    height_missing_per_episode: bool = False

    def __post_init__(self):
        _require("env.noise", [
            (k, getattr(self, k), 0.0 <= getattr(self, k) <= 1.0, "in [0, 1]")
            for k in ("height_missing", "height_missing_body", "height_missing_edge")]
            + [("height_offset", self.height_offset, self.height_offset >= 0.0, ">= 0")])


@dataclasses.dataclass(frozen=True)
class HeightMapConfig:
    """The local height map."""

    size: int = 21  # points per side
    spacing: float = 0.2  # m between points (21 x 0.2 -> 4 m x 4 m)
    offset: float = 0.4  # subtracted from base z - terrain z
    clip: float = 3.0  # |value| clip (m)
    # "Nothing behind a wall" (issue 24): with occlusion_samples > 0 a map point reads the
    # highest terrain between the base and it that stands above the sensor (base z +
    # sensor_height), where that is higher than its own: a wall hides what lies behind it, as
    # an elevation map built from the robot's own sensors has nothing past it. Read at
    # occlusion_samples - 1 points evenly along the segment from the base (<= 0.09 m apart at
    # 32 on the 4 m map; our walls are >= 0.2 m thick). 0: off (every policy before 2026-11-29,
    # whose maps read the floor behind the U tile's divider as a 0.8 m drop).
    occlusion_samples: int = 0
    sensor_height: float = 0.1  # m above the base

    def __post_init__(self):
        _require("env.height_map", [
            ("occlusion_samples", self.occlusion_samples,
             self.occlusion_samples == 0 or self.occlusion_samples >= 2, "0 (off) or >= 2"),
            ("sensor_height", self.sensor_height, self.sensor_height >= 0, ">= 0 m"),
        ])


@dataclasses.dataclass(frozen=True)
class RandomizationConfig:
    """Domain randomisation, per robot, resampled at every reset (off in evaluation)."""

    enabled: bool = True
    friction: tuple[float, float] = (0.4, 1.2)
    added_mass: tuple[float, float] = (-1.0, 2.0)  # kg on the trunk
    com_shift: float = 0.03  # m, uniform +- on the trunk CoM in x, y, z
    motor_strength: tuple[float, float] = (0.9, 1.1)  # scales the torque per joint
    kp_scale: tuple[float, float] = (0.9, 1.1)
    kd_scale: tuple[float, float] = (0.9, 1.1)
    push_interval_s: float = 8.0  # a push every this many seconds (0: never)
    push_velocity: float = 0.5  # m/s, uniform +- added to the base xy velocity
    # What a real Go2 needs (issue 24; the defaults leave the env as it was):
    # pushes only while the base is over the flights (between the tile's floor and top
    # heights), at random steps, one per push_interval_s on average
    push_on_stairs: bool = False
    # N m s/rad, uniform per robot, the joints' passive damping (the MJCF's 0.1 when ()); the
    # Go2 description has 2
    joint_damping: tuple[float, ...] = ()
    # how joint_damping is drawn: "uniform", or "log" (uniform in its logarithm, lo > 0: over
    # [0.1, 2] as many robots under 0.45 as above, where the delay costs most)
    joint_damping_draw: str = "uniform"
    # s, uniform per robot in whole physics steps: a new PD target takes effect this much
    # later (the previous one holds until then); at most one policy step
    action_delay_s: tuple[float, float] = (0.0, 0.0)
    # m, uniform per robot: the base's release height above the spawn floor at reset (() : the
    # env's spawn_height, which evaluation keeps; the nominal pose's feet touch at ~0.32)
    spawn_height: tuple[float, ...] = ()

    def __post_init__(self):
        d, lag, h = self.joint_damping, self.action_delay_s, self.spawn_height
        _require("env.randomization", [
            ("joint_damping", list(d), not d or (len(d) == 2 and 0.0 <= d[0] <= d[1]),
             "() or [lo, hi] with 0 <= lo <= hi"),
            ("joint_damping_draw", self.joint_damping_draw,
             self.joint_damping_draw in ("uniform", "log"), "'uniform' or 'log'"),
            ("joint_damping", list(d), self.joint_damping_draw == "uniform" or not d or d[0] > 0,
             "lo > 0 for joint_damping_draw = 'log'"),
            ("action_delay_s", list(lag), 0.0 <= lag[0] <= lag[1], "[lo, hi], 0 <= lo <= hi"),
            ("spawn_height", list(h), not h or (len(h) == 2 and 0.0 < h[0] <= h[1]),
             "() or [lo, hi] with 0 < lo <= hi")])


@dataclasses.dataclass(frozen=True)
class RouteConfig:
    """The route the waypoint follows, perturbed per episode (goal_mode "waypoint" only), as a
    building map's route would be off: resampled to a coarse polyline, its corners cut, shifted
    sideways. Rewards, success and the curriculum keep the true centre-line and goal."""

    perturb_prob: float = 0.0  # chance that an episode's route is perturbed (0: off)
    lateral: float = 0.33  # largest sideways shift, a fraction of the stair's clear width
    # chance that a perturbed route's shift is the largest itself (either side), not uniform up
    # to it: the evaluation's offset routes sit at the bound, which a uniform draw rarely gives
    lateral_at_bound: float = 0.0
    corner_cut_m: float = 1.0  # largest half-span of the corner cutting (m)
    coarse_points: tuple[int, int] = (3, 8)  # the route resampled to this many points

    def __post_init__(self):
        lo, hi = self.coarse_points
        _require("env.route", [
            ("perturb_prob", self.perturb_prob, 0.0 <= self.perturb_prob <= 1.0, "in [0, 1]"),
            ("lateral", self.lateral, 0.0 <= self.lateral <= 0.5, "in [0, 0.5]"),
            ("lateral_at_bound", self.lateral_at_bound, 0.0 <= self.lateral_at_bound <= 1.0,
             "in [0, 1]"),
            ("corner_cut_m", self.corner_cut_m, self.corner_cut_m >= 0.0, ">= 0"),
            ("coarse_points", [lo, hi], 2 <= lo <= hi, "[lo, hi] with 2 <= lo <= hi")])


@dataclasses.dataclass(frozen=True)
class GoalDrawConfig:
    """Per-episode goals anywhere on the raised stairs, the authors' stage-2 goals (issue 21;
    env.goals). Off: every episode's goal is its tile's (on the top landing)."""

    enabled: bool = False
    min_rise: float = 0.2  # m: goals lie on the centre-line at least this far above the floor
    random_yaw: bool = True  # goal yaw uniform in [-pi, pi] (false: the line's heading there)
    stationary_prob: float = 0.05  # chance that the goal is the spawn pose itself

    def __post_init__(self):
        _require("env.goal_draw", [
            ("min_rise", self.min_rise, self.min_rise >= 0.0, ">= 0"),
            ("stationary_prob", self.stationary_prob, 0.0 <= self.stationary_prob <= 1.0,
             "in [0, 1]")])


@dataclasses.dataclass(frozen=True)
class EnvConfig:
    """The stair env."""

    robot: rb.RobotConfig = rb.RobotConfig()
    rewards: rw.RewardConfig = rw.STAGE1
    curriculum: cur.CurriculumConfig = cur.CurriculumConfig()
    noise: NoiseConfig = NoiseConfig()
    height_map: HeightMapConfig = HeightMapConfig()
    randomization: RandomizationConfig = RandomizationConfig()
    route: RouteConfig = RouteConfig()
    goal_draw: GoalDrawConfig = GoalDrawConfig()
    decimation: int = 4  # physics steps per policy step (0.005 s x 4 -> 50 Hz)
    episode_length_s: float = 10.0
    action_clip: float = 5.0  # |action| clip before scaling
    max_tilt: float = 1.0  # rad; tilting further ends the episode
    min_base_height: float = 0.12  # m above the terrain under the base; lower ends the episode
    # "The terrain under the base" for that ending: the mean height at 5 points on a low_line_m
    # segment along the base's heading, centred under it (within the trunk's 0.38 m, so a side
    # wall never enters it); 0: the single point under the base (the rule of every result before
    # the generalist's second run). On a stair the point under a base holding a steady height
    # above the slope jumps a whole riser at every step nose, so at 17.8 cm risers the point
    # rule ended climbing robots (docs/diagnosis_code_suite.md); a 0.3 m segment (about a
    # tread) follows the slope instead. On flat ground both rules are the same.
    low_line_m: float = 0.0
    # The `tilt` ending's "upright": 0, the world's vertical (every result so far); > 0, the
    # normal of the terrain's slope along the base's heading, a line fitted to the terrain height
    # at 9 points on a tilt_slope_m segment centred under the base. On a 19.7 / 25.4 cm stair
    # (37.8 deg) the world rule ends a climbing robot pitched 57 deg nose up, 19 deg off the
    # stair's slope; with a 0.8 m segment (about three treads) the rule reads the pitch against
    # the stair (docs/results.md 8p). On flat ground both rules are the same.
    tilt_slope_m: float = 0.0
    terminate_on_trunk_contact: bool = True  # training only; off in evaluation
    # rad: the spawn yaw is the tile's +- this (the authors' stage 2: pi, any heading); < 0:
    # the tile's own half-range (45 deg on the paper families)
    spawn_yaw_half_range: float = -1.0
    spawn_height: float = 0.36  # base height above the spawn floor at reset (m)
    spawn_margin: float = 0.15  # m taken off each side of a tile's spawn rectangle: a Go2 turned
    # 45 deg reaches ~0.45 m from its centre, more than the terrain's 0.35 m wall clearance
    joint_noise_at_reset: float = 0.1  # rad, uniform +- around the nominal pose (0 in evaluation)
    success_distance: float = 0.5  # planar m
    success_speed: float = 0.3  # m/s
    success_hold_s: float = 0.5  # s the success condition must hold
    # What the goal observation points at. "final": the tile's goal (the paper's). "waypoint":
    # a point `waypoint_lookahead_m` further along the stair's centre-line than the robot's own
    # projection on it, with the centre-line's heading there; the final goal (and its yaw) once
    # the goal is closer along the line than the lookahead. Ours, not the paper's: a building's
    # stair centre-line is known from its map, and a goal behind the wall of a U-turn otherwise
    # pulls a stage-1 policy straight into the wall. Rewards, success and the curriculum always
    # use the final goal.
    goal_mode: Literal["final", "waypoint"] = "final"
    waypoint_lookahead_m: float = 1.0
    # The waypoint's yaw: "ahead", the centre-line's heading at the waypoint (every policy to
    # 2026-11-28); "here", its heading at the robot's own projection, so that a corner ahead turns
    # the yaw only once the robot reaches it. Why (docs/diagnosis_code_suite.md, session 24): on
    # the code suite's 1.12 m landings the 1 m waypoint passes the corner 1.6 treads before the
    # flight's top, its yaw turns by 90 degrees, and the robot turns on the steep flight and falls.
    # "chord": the heading from the robot's projection to the waypoint, which turns smoothly
    # through a corner and leads the robot round a curve by half the lookahead. A training choice,
    # not an evaluation setting (a policy is run with the rule it trained with); as a diagnostic, a
    # policy trained "ahead" and run "here" climbed those flights but lost the spiral and the
    # winder, run "chord" it was at or above its own rule on all 12 commercial cases.
    waypoint_heading: Literal["ahead", "here", "chord"] = "ahead"
    # Policy steps of history in the observation (env.observation.history_terms: the joint
    # positions and actions of that many earlier steps); 0: one frame, as every published policy.
    obs_history: int = 0
    # The action delay as an observation term (env.observation.DELAY_TERM, after the history):
    # the time a PD target waits before it takes effect, which a robot program measures once
    # (command to motor) and the env knows per robot (randomization.action_delay_s, or
    # robot.action_delay_s). Why (docs/deploy.md "The corner, trained"): one frame cannot tell a
    # 20 ms delay from none, and a policy trained over both holds only one diagonal of the
    # damping x delay square; false: not observed, as every published policy.
    obs_action_delay: bool = False
    # false (with obs_action_delay): the critic alone reads the delay, the actor reads 0 there
    # (an asymmetric critic: the return's dependence on the delay in the value baseline, one
    # policy for every delay; the sidecar gives the term scale 0, so a robot program writes 0).
    obs_action_delay_actor: bool = True
    # The leg joints' passive damping (drawn per robot by randomization.joint_damping, else the
    # robot's) as an input of the critic alone (observation.DAMPING_TERM, after the delay; the
    # actor reads 0 there, the sidecar gives it scale 0): the return at damping 0.1 with a long
    # delay is far below the rest (docs/results.md 8ac-8ae), a baseline that cannot see it mixes
    # the two.
    obs_joint_damping: bool = False

    def __post_init__(self):
        lag, step = self.randomization.action_delay_s[1], self.robot.timestep * self.decimation
        fixed = self.robot.action_delay_s
        _require("env", [
            ("tilt_slope_m", self.tilt_slope_m, self.tilt_slope_m >= 0,
             ">= 0 (m; 0: tilt from the world's vertical)"),
            ("obs_history", self.obs_history,
             isinstance(self.obs_history, int) and 0 <= self.obs_history <= 50,
             "an integer in [0, 50] (policy steps)"),
            ("obs_action_delay", self.obs_action_delay, isinstance(self.obs_action_delay, bool),
             "true or false"),
            ("obs_joint_damping", self.obs_joint_damping,
             isinstance(self.obs_joint_damping, bool), "true or false"),
            ("obs_action_delay_actor", self.obs_action_delay_actor,
             self.obs_action_delay_actor is True
             or (self.obs_action_delay_actor is False and self.obs_action_delay),
             "true, or false with obs_action_delay true (the critic alone reads the delay)"),
            ("randomization.action_delay_s", lag, lag <= step + 1e-9,
             f"at most one policy step ({step:g} s)"),
            ("robot.action_delay_s", fixed, 0.0 <= fixed <= step + 1e-9,
             f"in [0, one policy step ({step:g} s)]"),
            ("robot.implicit_damping", self.robot.implicit_damping,
             not self.robot.implicit_damping
             or self.robot.solver_iterations >= rb.IMPLICIT_MIN_ITERATIONS,
             f"false unless env.robot.solver_iterations >= {rb.IMPLICIT_MIN_ITERATIONS} (it has "
             f"{self.robot.solver_iterations}: the joints run away, sim.robot."
             "IMPLICIT_MIN_ITERATIONS; physics 'lean_implicit' is lean with 4)"),
            ("waypoint_heading", self.waypoint_heading,
             self.waypoint_heading in ("ahead", "here", "chord"), "'ahead', 'here' or 'chord'"),
            ("route.perturb_prob", self.route.perturb_prob,
             self.route.perturb_prob == 0 or self.goal_mode == "waypoint",
             "0 unless env.goal_mode = 'waypoint' (the route is what the waypoint follows)"),
            ("goal_draw.enabled", self.goal_draw.enabled,
             not self.goal_draw.enabled or self.goal_mode == "final",
             "false unless env.goal_mode = 'final' (the waypoint leads to the tile's goal)")])


def evaluation_config(config: EnvConfig, episode_length_s: float | None = None) -> EnvConfig:
    """The same env for evaluation: no noise, no randomisation, no trunk ending, no curriculum."""
    return dataclasses.replace(
        config,
        noise=dataclasses.replace(config.noise, enabled=False),
        randomization=dataclasses.replace(config.randomization, enabled=False),
        route=dataclasses.replace(config.route, perturb_prob=0.0),
        goal_draw=dataclasses.replace(config.goal_draw, enabled=False),  # the tiles' goals
        spawn_yaw_half_range=-1.0,  # the tiles' spawn headings
        curriculum=dataclasses.replace(config.curriculum, enabled=False),
        terminate_on_trunk_contact=False,
        joint_noise_at_reset=0.0,
        episode_length_s=episode_length_s or config.episode_length_s,
    )


def leg_damping(robot: rb.RobotConfig) -> float:
    """N m s/rad on every leg joint of a robot config: its joint_damping, else the MJCF's."""
    return rb.JOINT_DAMPING if robot.joint_damping is None else robot.joint_damping


def env_config_from(saved: dict[str, Any] | None, overrides: Sequence[str] = ()) -> EnvConfig:
    """The EnvConfig of a saved env table (a policy's, see rl.policy.saved_config; None: the
    defaults) with ``overrides`` ("robot.physics=reference", ...) applied."""
    data = to_dict(EnvConfig()) if saved is None else saved
    for item in overrides:  # in order: a physics preset sets the fields it names
        data = rb.expand_physics_in(apply_overrides(data, [item]), "robot")
    return from_dict(EnvConfig, data, prefix="env")
