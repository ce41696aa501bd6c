"""Policies and physics options checked against MuJoCo itself (`mjx_stairs.sim.box_world`).

Two measurements, both from the same starting states as an MJX evaluation with the same seed:
- `success_in_ground_truth`: the policy closed-loop on the box staircase in CPU MuJoCo, the
  evaluation protocol of `evaluate.success_by_level` (same spawns, observation, success and fall
  rules), one episode per robot;
- `first_second`: from states on the stairs, the same actions replayed open-loop for one second in
  the ground truth and in each MJX physics option: base position error, net vertical contact force.

What the ground truth shares with the env is the bookkeeping, not the physics: the observation
(height map sampled from the atlas grid, so the policy perceives the same staircase), the goal,
and the success and fall rules. Everything between a PD target and the next state is MuJoCo's.
"""

from __future__ import annotations

import dataclasses
import time
from typing import Any, Callable, NamedTuple, Sequence

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
from mujoco.mjx._src import support

from mjx_stairs.env import endings, observation
from mjx_stairs.env import stair_env as envlib
from mjx_stairs.env.geometry import quat_to_mat, quat_yaw
from mjx_stairs.rl.policy import Policy, policy_action
from mjx_stairs.sim import box_world as bw
from mjx_stairs.sim import robot as rb
from mjx_stairs.study.evaluate import CellSpec, cell_env, cell_records, initial_states
from terrains.boxes import grid_boxes

TILE_MARGIN = 4
"""Grid points beyond a tile's own kept around it in its box world (its walls stand inside)."""


def tile_model(env: envlib.StairEnv, heights: np.ndarray, tile: int, tile_size: float,
               solver: bw.SolverConfig = bw.DEFAULT_SOLVER,
               terrain: str = "boxes") -> mujoco.MjModel:
    """The box world of one atlas tile, in world coordinates (so env states carry over);
    `heights` [NY, NX] the atlas heights (`env.terrain.heights()`). `terrain="heightfield"`:
    the atlas heightfield instead of boxes (the shape MJX sees)."""
    if terrain == "heightfield":
        return bw.build_model(np.zeros((0, 6)), env.config.robot, solver,
                              heightfield=(heights, env.resolution))
    if terrain != "boxes":
        raise ValueError(f"terrain must be 'boxes' or 'heightfield', got {terrain!r}")
    res = env.resolution
    n = int(round(tile_size / res))
    ox, oy = (int(round(v / res)) for v in env.tile_origin[tile])
    x0, y0 = max(ox - TILE_MARGIN, 0), max(oy - TILE_MARGIN, 0)
    x1 = min(ox + n + TILE_MARGIN, heights.shape[1])
    y1 = min(oy + n + TILE_MARGIN, heights.shape[0])
    boxes = grid_boxes(heights[y0:y1, x0:x1], res, origin=(x0 * res, y0 * res))
    return bw.build_model(boxes, env.config.robot, solver)


class _Start(NamedTuple):
    """An evaluation's robots, ready for the ground truth: the MJX env (for observation and
    rules), the robots' first states and infos, their tiles and each tile's MuJoCo model."""

    env: envlib.StairEnv
    state: Any
    info: dict
    tiles: np.ndarray
    models: list[mujoco.MjModel]  # one per robot (shared by robots of a tile)


def _start(policy: Policy, spec: CellSpec, solver: bw.SolverConfig, terrain: str) -> _Start:
    env = cell_env(policy, spec)
    state = initial_states(env, spec)
    info = {k: v for k, v in state.info.items() if k != "final_obs"}
    tiles = np.asarray(info["tile"])
    heights = env.terrain.heights()
    by_tile = {int(t): tile_model(env, heights, int(t), spec.tile_size, solver, terrain)
               for t in np.unique(tiles)}
    return _Start(env, state, info, tiles, [by_tile[int(t)] for t in tiles])


class _Controller:
    """The policy as the env runs it: clean observation, mean action, clip, PD target."""

    def __init__(self, env: envlib.StairEnv, policy: Policy, info: dict):
        self._observe = jax.jit(jax.vmap(lambda q, v, i: env.observe(q, v, i)["state"]))
        self._act = jax.jit(lambda o: policy_action(policy, o))
        self._info = dict(info)
        self._c = env.config
        self._joints = np.asarray(env.robot.ids.qpos_joints)
        self._seen = None  # (joint positions, last action) of the previous call, for history

    def __call__(self, qpos: np.ndarray, qvel: np.ndarray, last_action: np.ndarray):
        """(action [B, 12], PD target [B, 12]) for the robots' state and last action; called
        once per control step (a policy with history keeps the previous calls' as the env
        does: env.stair_env's step)."""
        if self._c.obs_history and self._seen is not None:
            q, a = self._seen
            for key, new in (("joint_pos_history", q - rb.NOMINAL_JOINT_POS),
                             ("action_history", a)):
                self._info[key] = observation.shift_in(self._info[key],
                                                       jnp.asarray(new, jnp.float32))
        self._seen = (np.asarray(qpos)[:, self._joints], np.asarray(last_action))
        self._info["last_action"] = jnp.asarray(last_action)
        obs = self._observe(jnp.asarray(qpos, jnp.float32), jnp.asarray(qvel, jnp.float32),
                            self._info)
        c = self._c
        a = np.clip(np.asarray(self._act(obs)), -c.action_clip, c.action_clip)
        return a, self.target(a)

    def target(self, action: np.ndarray) -> np.ndarray:
        """The PD target [B, 12] of a (clipped) action."""
        return rb.NOMINAL_JOINT_POS + self._c.robot.action_scale * action


@dataclasses.dataclass
class _Episodes:
    """Per-robot bookkeeping of the evaluation protocol, in numpy."""

    n: int
    hold_steps: int
    success: np.ndarray = None  # type: ignore[assignment]
    fell: np.ndarray = None  # type: ignore[assignment]
    count: np.ndarray = None  # type: ignore[assignment]
    time_to_goal: np.ndarray = None  # type: ignore[assignment]

    def __post_init__(self):
        self.success = np.zeros(self.n, bool)
        self.fell = np.zeros(self.n, bool)
        self.count = np.zeros(self.n, np.int64)
        self.time_to_goal = np.full(self.n, np.nan)

    @property
    def active(self) -> np.ndarray:
        return ~(self.success | self.fell)


def _endings(env: envlib.StairEnv, qpos: np.ndarray, qvel: np.ndarray, goal: np.ndarray):
    """(close [N], fell [N]) by the env's rules (eval settings: no trunk-contact ending)."""
    c = env.config
    pos = qpos[:, :3]
    body_z = quat_to_mat(qpos[:, 3:7].T, xp=np)[:, 2].T  # [N, 3]: each body's z axis
    height = lambda x, y: np.asarray(env.terrain_height(jnp.asarray(x), jnp.asarray(y)))
    yaw = quat_yaw(qpos[:, 3:7].T, xp=np)
    slope = endings.slope_along(height, pos[:, 0], pos[:, 1], yaw, c.tilt_slope_m, xp=np)
    tilted = endings.upright(body_z, yaw, slope, xp=np) < np.cos(c.max_tilt)
    ground = endings.ground_under(height, pos[:, 0], pos[:, 1], yaw, c.low_line_m, xp=np)
    too_low = pos[:, 2] - ground < c.min_base_height
    wx, wy = (np.asarray(env.atlas_shape[::-1]) - 1) * env.resolution
    outside = (pos[:, 0] < 0) | (pos[:, 1] < 0) | (pos[:, 0] > wx) | (pos[:, 1] > wy)
    bad = ~(np.all(np.isfinite(qpos), 1) & np.all(np.isfinite(qvel), 1))
    planar = np.linalg.norm(goal[:, :2] - pos[:, :2], axis=1)
    close = (planar < c.success_distance) & (np.linalg.norm(qvel[:, :2], axis=1) < c.success_speed)
    return close, tilted | too_low | outside | bad


def closed_loop(env: envlib.StairEnv, policy: Policy, info: dict, batch: bw.Batch,
                goal: np.ndarray, last_action: np.ndarray, steps: int,
                record: Callable[[bw.Batch, np.ndarray], None] | None = None) -> _Episodes:
    """The policy closed-loop on `batch` for up to `steps` policy steps by the evaluation's rules
    (goal [B, 4]; a robot stops once it has succeeded or fallen). `record(batch, last_action)`
    after every step; without it the loop ends as soon as every robot has stopped."""
    control = _Controller(env, policy, info)
    c = env.config
    ep = _Episodes(batch.qpos.shape[0], max(1, int(round(c.success_hold_s / env.dt))))
    # the robot's fixed action delay (robot.action_delay_s; evaluation draws none): physics
    # steps that still hold the previous target, as the env's actuation does
    delay = c.robot.action_delay_steps
    for k in range(steps):
        active = ep.active
        if record is None and not active.any():
            break
        before = control.target(last_action) if delay else None
        a, target = control(batch.qpos, batch.qvel, last_action)
        batch.step(target, c.decimation, active, previous=before, delay=delay)
        last_action = np.where(active[:, None], a, last_action)
        close, fell = _endings(env, batch.qpos, batch.qvel, goal)
        ep.count = np.where(active, np.where(close, ep.count + 1, 0), ep.count)
        done_now = active & (ep.count >= ep.hold_steps)
        ep.time_to_goal[done_now] = (k + 1) * env.dt
        ep.success |= done_now
        ep.fell |= active & ~done_now & fell
        if record is not None:
            record(batch, last_action)
    return ep


def success_in_ground_truth(
    policy: Policy, spec: CellSpec, solver: bw.SolverConfig = bw.DEFAULT_SOLVER,
    nthread: int | None = None, terrain: str = "boxes",
) -> dict[str, Any]:
    """`evaluate.success_by_cell` with CPU MuJoCo on box stairs in place of MJX.

    Robots start from the same states as the MJX evaluation of the same spec (same seed). A
    robot stops once it has succeeded or fallen (success is final in both).
    """
    env, state, info, tiles, models = _start(policy, spec, solver, terrain)
    B = tiles.shape[0]
    batch = bw.Batch(models, np.asarray(state.pipeline_state.qpos), nthread=nthread)
    t0 = time.time()
    ep = closed_loop(env, policy, info, batch, np.asarray(env.goals)[tiles],
                     np.zeros((B, 12), np.float32), env.episode_steps)
    batch.close()
    per_cell = ep.time_to_goal.reshape(len(spec.cells), -1)
    return cell_records(
        spec, ep.success, ep.fell, physics=f"mujoco_cpu_{terrain}",
        solver=dataclasses.asdict(solver), wall_s=time.time() - t0,
        mean_time_to_goal_s=[float(np.nanmean(t)) if np.isfinite(t).any() else None
                             for t in per_cell],
    )


# ----------------------------------------------------------------------------- first second


def _mjx_vertical_force(env: envlib.StairEnv, data) -> jax.Array:
    """|Net vertical contact force| (N) on one robot from its MJX data."""
    ncon = data._impl.contact.dist.shape[0]
    if ncon == 0:
        return jnp.zeros(())
    m = env.robot.mjx_model  # contact ids are static: efc addresses are host arrays in MJX
    f = jnp.stack([support.contact_force(m, data, i, True)[2] for i in range(ncon)])
    return jnp.abs(jnp.sum(jnp.where(data._impl.contact.dist < 0, f, 0.0)))


def first_second(
    policy: Policy, spec: CellSpec, options: dict[str, Sequence[str]], warmup_s: float = 2.0,
    horizon_s: float = 1.0, solver: bw.SolverConfig = bw.DEFAULT_SOLVER,
    replays: dict[str, Callable] | None = None,
) -> dict[str, Any]:
    """From the same states on the stairs, the same actions for `horizon_s` in the ground truth
    and in each MJX option ({name: env overrides}): base position error and contact force.
    `replays` ({name: fn(policy, spec, start, actions) -> (pos, force, done)}, as
    `replay_in_mjx`) adds other simulators (e.g. MuJoCo Warp) beside the options.

    The starting states: the spec's robots after `warmup_s` of the policy in the ground truth.
    The actions: the policy's, closed-loop in the ground truth; each MJX option replays them
    open-loop. Per option: the mean and 90th percentile over robots of the base position error
    at each policy step, and the mean |difference| of the total net vertical contact force.

    Long: the ground truth and each MJX option replayed side by side, step by step.
    """
    env, state, info, _, models = _start(policy, spec, solver, "boxes")
    robots = [(m, mujoco.MjData(m)) for m in models]
    for (_, d), q in zip(robots, np.asarray(state.pipeline_state.qpos), strict=True):
        d.qpos[:] = q
    control = _Controller(env, policy, info)
    c = env.config
    warm, steps = int(round(warmup_s / env.dt)), int(round(horizon_s / env.dt))
    start = None
    actions, gt_pos, gt_force = [], [], []
    last_action = np.zeros((len(robots), 12), np.float32)
    for k in range(warm + steps):
        qpos = np.stack([d.qpos.copy() for _, d in robots])
        qvel = np.stack([d.qvel.copy() for _, d in robots])
        if k == warm:
            start = (qpos, qvel, last_action.copy())
        a, target = control(qpos, qvel, last_action)
        for (m, d), q_target in zip(robots, target, strict=True):
            d.ctrl[:] = q_target
            for _ in range(c.decimation):
                mujoco.mj_step(m, d)
        last_action = a
        if k >= warm:
            actions.append(a)
            gt_pos.append(np.stack([d.qpos[:3].copy() for _, d in robots]))
            gt_force.append([bw.contact_summary(m, d)["vertical_force"] for m, d in robots])
    gt_pos, gt_force = np.array(gt_pos), np.array(gt_force)  # [T, B, 3], [T, B]
    cell = spec.cells[0]
    out = {"robots": len(robots), "warmup_s": warmup_s, "horizon_s": horizon_s,
           "cell": {"family": cell[0], "schedule": cell[1], "level": cell[2] + 1},
           "gt_mean_vertical_force_n": float(gt_force.mean()), "options": {}}
    runs = {name: (tuple(o), replay_in_mjx) for name, o in options.items()}
    runs.update({name: ((), fn) for name, fn in (replays or {}).items()})
    for name, (overrides, replay) in runs.items():
        pos, force, done = replay(policy, dataclasses.replace(spec, env_overrides=overrides),
                                  start, actions)
        # A robot whose MJX episode ended (a fall) is reset by the env: compared until then.
        ended = np.cumsum(done, axis=0) > 0  # [T, B]
        err = np.where(ended, np.nan, np.linalg.norm(pos - gt_pos, axis=-1))  # [T, B]
        df = np.where(ended, np.nan, np.abs(force - gt_force))
        out["options"][name] = {
            "overrides": list(overrides),
            "pos_error_mean_m": [float(e) for e in np.nanmean(err, 1)],
            "pos_error_p90_m": [float(e) for e in np.nanpercentile(err, 90, axis=1)],
            "pos_error_at_horizon_mean_m": float(np.nanmean(err[-1])),
            "pos_error_at_horizon_p90_m": float(np.nanpercentile(err[-1], 90)),
            "pos_error_at_horizon_max_m": float(np.nanmax(err[-1])),
            "force_abs_diff_mean_n": _nanmean(df),
            "mean_vertical_force_n": _nanmean(np.where(ended, np.nan, force)),
            "episodes_ended_in_mjx": int(ended[-1].sum()),
        }
    return out


def _nanmean(x: np.ndarray) -> float | None:
    """The mean of the finite entries; None where there are none (a replay without forces)."""
    x = np.asarray(x, np.float64)
    return float(np.nanmean(x)) if np.isfinite(x).any() else None


def replay_in_mjx(policy: Policy, spec: CellSpec, start, actions):
    """Positions [T, B, 3], net vertical contact forces [T, B] and episode ends [T, B] in the
    MJX physics of `spec`'s overrides, replaying `actions` [T][B, 12] from `start` = (qpos, qvel,
    last action) on the tiles the spec's seed places its robots on."""
    env = cell_env(policy, spec)
    state0 = initial_states(env, spec)
    qpos, qvel, last = start
    data = state0.pipeline_state.replace(qpos=jnp.asarray(qpos, jnp.float32),
                                         qvel=jnp.asarray(qvel, jnp.float32))
    st = state0.replace(pipeline_state=data, info=dict(state0.info, last_action=jnp.asarray(last)))

    def one(s, a):
        s = jax.vmap(env.step)(s, a)
        force = jax.vmap(lambda d: _mjx_vertical_force(env, d))(s.pipeline_state)
        return s, (s.pipeline_state.qpos[:, :3], force, s.done > 0)

    _, (pos, force, done) = jax.jit(lambda s, a: jax.lax.scan(one, s, a))(
        st, jnp.asarray(np.stack(actions)))
    return np.asarray(pos, np.float64), np.asarray(force, np.float64), np.asarray(done)
