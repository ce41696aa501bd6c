"""Policies and physics options checked against MuJoCo itself (`mjx_stairs.box_world`).

Two measurements, both from the same starting states as an MJX evaluation with the same seed:
- `success_in_ground_truth`: the policy closed-loop on the box staircase in CPU MuJoCo, the
  evaluation protocol of `evaluate.success_by_level` (same spawns, observation, success and fall
  rules), one episode per robot;
- `first_second`: from states on the stairs, the same actions replayed open-loop for one second in
  the ground truth and in each MJX physics option: base position error and contact normal force.

What the ground truth shares with the env is the bookkeeping, not the physics: the observation
(height map sampled from the atlas grid, so the policy perceives the same staircase), the goal,
and the success and fall rules. Everything between a PD target and the next state is MuJoCo's.
"""

from __future__ import annotations

import dataclasses
import time
from typing import Any, Sequence

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
from mujoco.mjx._src import support

from mjx_stairs import box_world as bw
from mjx_stairs import env as envlib
from mjx_stairs import robot as rb
from mjx_stairs.evaluate import EvalSpec, make_eval_env
from mjx_stairs.train import Policy, policy_action
from terrains.boxes import grid_boxes

TILE_MARGIN = 4
"""Grid points beyond a tile's own kept around it in its box world (its walls stand inside)."""


def env_heights(env: envlib.StairEnv) -> np.ndarray:
    """[NY, NX] the atlas heights back from the env's MuJoCo model (float32 rounding)."""
    mj = env.robot.mj_model
    ny, nx = env.atlas_shape
    hid = env.robot.ids.hfield_geom
    data = np.asarray(mj.hfield_data, np.float64).reshape(ny, nx)
    return data * float(mj.hfield_size[0][2]) + float(mj.geom_pos[hid][2])


def tile_model(env: envlib.StairEnv, tile: int, tile_size: float,
               solver: bw.SolverConfig = bw.DEFAULT_SOLVER) -> mujoco.MjModel:
    """The box world of one atlas tile, in world coordinates (so env states carry over)."""
    res = env.resolution
    heights = env_heights(env)
    n = int(round(tile_size / res))
    ox, oy = (int(round(v / res)) for v in env.tile_origin[tile])
    x0, y0 = max(ox - TILE_MARGIN, 0), max(oy - TILE_MARGIN, 0)
    x1 = min(ox + n + TILE_MARGIN, heights.shape[1])
    y1 = min(oy + n + TILE_MARGIN, heights.shape[0])
    boxes = grid_boxes(heights[y0:y1, x0:x1], res, origin=(x0 * res, y0 * res))
    return bw.build_model(boxes, env.config.robot, solver)


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
    x, y = qpos[:, 4], qpos[:, 5]
    up_z = 1 - 2 * (x * x + y * y)  # R[2, 2]: the body's z axis against the world's
    tilted = up_z < np.cos(c.max_tilt)
    ground = np.asarray(env.terrain_height(jnp.asarray(pos[:, 0]), jnp.asarray(pos[:, 1])))
    too_low = pos[:, 2] - ground < c.min_base_height
    wx, wy = (np.asarray(env.atlas_shape[::-1]) - 1) * env.resolution
    outside = (pos[:, 0] < 0) | (pos[:, 1] < 0) | (pos[:, 0] > wx) | (pos[:, 1] > wy)
    bad = ~(np.all(np.isfinite(qpos), 1) & np.all(np.isfinite(qvel), 1))
    planar = np.linalg.norm(goal[:, :2] - pos[:, :2], axis=1)
    close = (planar < c.success_distance) & (np.linalg.norm(qvel[:, :2], axis=1) < c.success_speed)
    return close, tilted | too_low | outside | bad


def success_in_ground_truth(
    policy: Policy, spec: EvalSpec, solver: bw.SolverConfig = bw.DEFAULT_SOLVER,
    nthread: int | None = None,
) -> dict[str, Any]:
    """`evaluate.success_by_level` with CPU MuJoCo on box stairs in place of MJX.

    Robots start from the same states as the MJX evaluation with the same spec (same seed). A
    robot stops once it has succeeded or fallen (success is final in both).
    """
    env, levels = make_eval_env(policy, spec)
    n_levels, per = len(levels), spec.robots_per_level
    B = n_levels * per
    row = jnp.repeat(jnp.arange(n_levels, dtype=jnp.int32), per)
    keys = jax.random.split(jax.random.PRNGKey(spec.seed), B)
    state = jax.jit(jax.vmap(env.reset_at))(keys, row, jnp.zeros(B, jnp.int32))
    info = {k: v for k, v in state.info.items() if k != "final_obs"}
    tiles = np.asarray(info["tile"])
    models = {int(t): tile_model(env, int(t), spec.tile_size, solver) for t in np.unique(tiles)}
    batch = bw.Batch([models[int(t)] for t in tiles], np.asarray(state.pipeline_state.qpos),
                     nthread=nthread)
    goal = np.asarray(env.goals)[tiles]
    observe = jax.jit(jax.vmap(env.observe))
    act = jax.jit(lambda o: policy_action(policy, o))
    c = env.config
    ep = _Episodes(B, max(1, int(round(c.success_hold_s / env.dt))))
    last_action = np.zeros((B, 12), np.float32)
    t0 = time.time()
    for k in range(env.episode_steps):
        active = ep.active
        if not active.any():
            break
        info["last_action"] = jnp.asarray(last_action)
        a = np.clip(np.asarray(act(observe(jnp.asarray(batch.qpos, jnp.float32),
                                            jnp.asarray(batch.qvel, jnp.float32), info))),
                    -c.action_clip, c.action_clip)
        batch.step(rb.NOMINAL_JOINT_POS + c.robot.action_scale * a, c.decimation, active)
        last_action = np.where(active[:, None], a, last_action)
        close, fell = _endings(env, batch.qpos, batch.qvel, goal)
        ep.count = np.where(close & active, ep.count + 1, np.where(active, 0, ep.count))
        done_now = active & (ep.count >= ep.hold_steps)
        ep.time_to_goal[done_now] = (k + 1) * env.dt
        ep.success |= done_now
        ep.fell |= active & ~done_now & fell
    batch.close()
    wall = time.time() - t0
    shape = (n_levels, per)
    return {
        "physics": "ground_truth",
        "family": spec.family,
        "schedule": spec.schedule,
        "levels": [lv + 1 for lv in levels],
        "success": [float(s) for s in ep.success.reshape(shape).mean(1)],
        "fell": [float(f) for f in ep.fell.reshape(shape).mean(1)],
        "mean_time_to_goal_s": [float(np.nanmean(t)) if np.isfinite(t).any() else None
                                for t in ep.time_to_goal.reshape(shape)],
        "robots_per_level": per,
        "episode_length_s": spec.episode_length_s,
        "seed": spec.seed,
        "solver": dataclasses.asdict(solver),
        "wall_s": wall,
    }


# ----------------------------------------------------------------------------- first second


def _mjx_normal_force(env: envlib.StairEnv, data) -> jax.Array:
    """Total contact normal force (N) on one robot from its MJX data."""
    ncon = data._impl.contact.dist.shape[0]
    if ncon == 0:
        return jnp.zeros(())
    f = jax.vmap(lambda i: support.contact_force(env.robot.mjx_model, data, i)[0])(
        jnp.arange(ncon))
    return jnp.sum(jnp.where(data._impl.contact.dist < 0, f, 0.0))


def first_second(
    policy: Policy, spec: EvalSpec, options: dict[str, Sequence[str]], warmup_s: float = 2.0,
    horizon_s: float = 1.0, solver: bw.SolverConfig = bw.DEFAULT_SOLVER,
) -> dict[str, Any]:
    """From the same states on the stairs, the same actions for `horizon_s` in the ground truth
    and in each MJX option ({name: env overrides}): base position error and contact force.

    The starting states: the robots of `spec` (its first level) after `warmup_s` of the policy
    in the ground truth. The actions: the policy's, closed-loop in the ground truth; each MJX
    option replays them open-loop. Returns per option the mean and 90th percentile over robots
    of the base position error at each policy step and the mean |normal force difference|.
    """
    spec = dataclasses.replace(spec, levels=spec.levels[:1] or (0,))
    env, _ = make_eval_env(policy, spec)
    B = spec.robots_per_level
    keys = jax.random.split(jax.random.PRNGKey(spec.seed), B)
    state = jax.jit(jax.vmap(env.reset_at))(keys, jnp.zeros(B, jnp.int32), jnp.zeros(B, jnp.int32))
    info = {k: v for k, v in state.info.items() if k != "final_obs"}
    tiles = np.asarray(info["tile"])
    models = {int(t): tile_model(env, int(t), spec.tile_size, solver) for t in np.unique(tiles)}
    datas = [mujoco.MjData(models[int(t)]) for t in tiles]
    for d, q in zip(datas, np.asarray(state.pipeline_state.qpos), strict=True):
        d.qpos[:] = q
    observe = jax.jit(jax.vmap(env.observe))
    act = jax.jit(lambda o: policy_action(policy, o))
    c = env.config
    warm, steps = int(round(warmup_s / env.dt)), int(round(horizon_s / env.dt))
    qpos0 = qvel0 = None
    actions, gt_pos, gt_force = [], [], []
    last_action = np.zeros((B, 12), np.float32)
    for k in range(warm + steps):
        if k == warm:
            qpos0 = np.stack([d.qpos.copy() for d in datas])
            qvel0 = np.stack([d.qvel.copy() for d in datas])
            last0 = last_action.copy()
        info["last_action"] = jnp.asarray(last_action)
        qpos = jnp.asarray(np.stack([d.qpos for d in datas]), jnp.float32)
        qvel = jnp.asarray(np.stack([d.qvel for d in datas]), jnp.float32)
        a = np.clip(np.asarray(act(observe(qpos, qvel, info))), -c.action_clip, c.action_clip)
        target = rb.NOMINAL_JOINT_POS + c.robot.action_scale * a
        for i, d in enumerate(datas):
            d.ctrl[:] = target[i]
            for _ in range(c.decimation):
                mujoco.mj_step(models[int(tiles[i])], d)
        last_action = a
        if k >= warm:
            actions.append(a)
            gt_pos.append(np.stack([d.qpos[:3].copy() for d in datas]))
            gt_force.append([bw.contact_summary(models[int(tiles[i])], d)["normal_force"]
                             for i, d in enumerate(datas)])
    gt_pos, gt_force = np.array(gt_pos), np.array(gt_force)  # [T, B, 3], [T, B]
    out = {"robots": B, "warmup_s": warmup_s, "horizon_s": horizon_s, "options": {},
           "family": spec.family, "schedule": spec.schedule, "level": spec.levels[0] + 1,
           "gt_mean_normal_force": float(gt_force.mean())}
    for name, overrides in options.items():
        pos, force = replay_in_mjx(policy, spec, overrides, qpos0, qvel0, last0, actions, state)
        err = np.linalg.norm(pos - gt_pos, axis=-1)  # [T, B]
        out["options"][name] = {
            "overrides": list(overrides),
            "pos_error_mean_m": [float(e) for e in err.mean(1)],
            "pos_error_p90_m": [float(e) for e in np.percentile(err, 90, axis=1)],
            "pos_error_at_horizon_mean_m": float(err[-1].mean()),
            "force_abs_diff_mean_n": float(np.abs(force - gt_force).mean()),
            "mean_normal_force_n": float(force.mean()),
        }
    return out


def replay_in_mjx(policy, spec, overrides, qpos0, qvel0, last0, actions, state0):
    """Positions [T, B, 3] and contact normal forces [T, B] of MJX option `overrides` replaying
    `actions` [T][B, 12] from (qpos0, qvel0) on the same tiles as `state0`."""
    env, _ = make_eval_env(policy, dataclasses.replace(spec, env_overrides=tuple(overrides)))
    data = state0.pipeline_state.replace(qpos=jnp.asarray(qpos0, jnp.float32),
                                         qvel=jnp.asarray(qvel0, jnp.float32))
    info = dict(state0.info, last_action=jnp.asarray(last0))
    st = state0.replace(pipeline_state=data, info=info)

    def one(s, a):
        s = jax.vmap(env.step)(s, a)
        return s, (s.pipeline_state.qpos[:, :3],
                   jax.vmap(lambda d: _mjx_normal_force(env, d))(s.pipeline_state))

    _, (pos, force) = jax.jit(lambda s, a: jax.lax.scan(one, s, a))(
        st, jnp.asarray(np.stack(actions)))
    return np.asarray(pos, np.float64), np.asarray(force, np.float64)
