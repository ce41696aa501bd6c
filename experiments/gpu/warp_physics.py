"""MuJoCo Warp beside our physics (issues 22 and 19): `mjx.put_model(..., impl="warp")` with our
Go2 on the same atlas, its speed and its fidelity against the CPU MuJoCo ground truth.

The warp model is the env's own MuJoCo model (same MJCF, PD gains, solver iterations, atlas
heightfield) with the collision spheres as spheres, so that MuJoCo Warp collides them with the
heightfield through its own pipeline (our columns / nearest-point colliders are MJX-JAX only).
The PD law is the env's: clip(kp (q* - q) - kd qd, -limit, limit) at every physics step.

  python experiments/gpu/warp_physics.py rate OUT.json [--robots 4096] [--steps 20]
      physics only, random torques (as `mjx-stairs bench --parts physics`): MuJoCo Warp and the
      env's JAX physics (the config's, default the evaluation physics) in the same process
  python experiments/gpu/warp_physics.py success OUT.json [--robots 1000] [--cells 8,9]
      the published policies closed-loop with MuJoCo Warp as the physics (evaluation rules,
      the evaluation's starts, as the CPU ground truth runs them: ground_truth.closed_loop)
  python experiments/gpu/warp_physics.py first OUT.json [--robots 32] [--cells 3,8,15]
      the first second: from the ground truth's states after 2 s, its actions replayed
      open-loop in MuJoCo Warp (ground_truth.first_second)

The solver is the evaluation physics's (8 Newton iterations, 10 line-search steps; the cells'
env is built in the evaluation physics and only its spheres change). Needs warp-lang and
mujoco-warp (not in our dependencies): on the GPU host run.sh step `warp` installs them from the
parts carried by three calls before it (device `run` with carry [".whl_warp_a"], then
[".whl_warp_b"], then [".whl_warp_c"], each `true`, then carry [".whl_train"] and
`WHL=.whl_train bash experiments/gpu/run.sh 580 warp pack`, back to back on the warm machine).
Runs on the CPU too (JAX_PLATFORMS=cpu, PYTHONPATH=<site with warp>:.), slowly: 16 robots of
`stage2_u` on U-shaped test L1 closed-loop in 57 s on 2 cores (15 of 16 succeeded).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
from mujoco import mjx

from mjx_stairs.sim import robot as rb

sys.path.insert(0, str(Path(__file__).parent))
from fidelity import CELLS, POLICIES  # noqa: E402

CONTACTS_PER_ROBOT = 48
"""MuJoCo Warp's contact pool is shared by all worlds: this many per robot (20 spheres, 1-4
contacts each for those touching; a standing robot has 4-8)."""
CONSTRAINTS_PER_ROBOT = 256
"""Constraint rows per world (pyramidal: 4 per contact, plus joint limits)."""


def warp_model(env) -> mujoco.MjModel:
    """The env's MuJoCo model with plain collision spheres (MuJoCo's sphere-heightfield pairs)."""
    cfg = dataclasses.replace(env.config.robot, terrain_contacts="mjx")
    return rb.build_mj_model(env.terrain.heights(), env.resolution, cfg)


class WarpBatch:
    """N robots stepped by MuJoCo Warp, with what `ground_truth.closed_loop` uses of
    `box_world.Batch` (qpos, qvel, step), so the policy runs on it as on the ground truth."""

    def __init__(self, env, qpos: np.ndarray, qvel: np.ndarray | None = None):
        m = warp_model(env)
        n = qpos.shape[0]
        self.mx = mjx.put_model(m, impl="warp")
        c = env.config.robot
        qj, vj = env.robot.ids.qpos_joints, env.robot.ids.qvel_joints
        limit = jnp.asarray(rb.TORQUE_LIMIT * c.torque_scale)
        mx = self.mx

        def make(q, v):
            d = mjx.make_data(m, impl="warp", naconmax=n * CONTACTS_PER_ROBOT,
                              njmax=CONSTRAINTS_PER_ROBOT)
            return d.replace(qpos=q, qvel=v)

        v0 = np.zeros((n, m.nv)) if qvel is None else qvel
        self.data = jax.jit(jax.vmap(make))(jnp.asarray(qpos, jnp.float32),
                                           jnp.asarray(v0, jnp.float32))

        def step(data, target, active, substeps):
            def physics(d, _):
                tau = rb.pd_torque(target, d.qpos[:, qj], d.qvel[:, vj], c.kp, c.kd, limit)
                return jax.vmap(lambda x, t: mjx.step(mx, x.replace(ctrl=t)))(d, tau), None

            new = jax.lax.scan(physics, data, None, length=substeps)[0]
            keep = lambda a, b: jnp.where(active.reshape((-1,) + (1,) * (a.ndim - 1)), a, b)
            return new.replace(qpos=keep(new.qpos, data.qpos), qvel=keep(new.qvel, data.qvel))

        self._step = jax.jit(step, static_argnums=3)

    @property
    def qpos(self) -> np.ndarray:
        return np.asarray(self.data.qpos, np.float64)

    @property
    def qvel(self) -> np.ndarray:
        return np.asarray(self.data.qvel, np.float64)

    def step(self, q_target: np.ndarray, substeps: int, active: np.ndarray | None = None) -> None:
        on = np.ones(self.data.qpos.shape[0], bool) if active is None else active
        self.data = self._step(self.data, jnp.asarray(q_target, jnp.float32),
                               jnp.asarray(on), substeps)


def _policies(names: str | None):
    from mjx_stairs.rl.policy import load_policy

    keep = list(POLICIES) if not names else names.split(",")
    return {k: load_policy(POLICIES[k]) for k in keep}


def run_rate(out: Path, robots: int, steps: int, repeats: int, config: str,
             overrides: list[str]) -> None:
    """Physics-only env steps/s: MuJoCo Warp, then the env's own physics (bench_physics)."""
    from mjx_stairs.rl.sharding import make_mesh
    from mjx_stairs.study import bench
    from mjx_stairs.study.experiment import load, make_env

    cfg, _ = load(config, overrides, cpu=False)
    env = make_env(cfg)
    mesh = make_mesh()
    rec = {"config": config, "overrides": overrides, "robots": robots, "steps": steps,
           "device": jax.devices()[0].device_kind, "jax": jax.__version__,
           "mujoco": mujoco.__version__}
    data = jax.jit(jax.vmap(env.reset))(jax.random.split(jax.random.PRNGKey(0), robots))
    batch = WarpBatch(env, np.asarray(data.pipeline_state.qpos))
    rec["warp"] = bench.bench_physics(env, robots, steps, repeats, mesh, batch.mx, batch.data)
    final = rec["warp"].pop("data")
    rec["warp"]["nacon_last"] = int(np.asarray(final._impl.nacon).max())
    print(f"[warp] {rec['warp']}", flush=True)
    rec["jax"] = bench.bench_physics(env, robots, steps, repeats, mesh)
    rec["jax"].pop("data")
    print(f"[jax] {rec['jax']}", flush=True)
    _write(out, rec)


def run_success(out: Path, robots: int, cells: list[int], policies: str | None) -> None:
    """Success per cell with MuJoCo Warp as the physics, from the evaluation's starts."""
    from mjx_stairs.study import ground_truth as gt
    from mjx_stairs.study.evaluate import CellSpec, cell_env, cell_records, initial_states

    rec = {"physics": "mujoco_warp", "device": jax.devices()[0].device_kind, "policies": {}}
    for name, policy in _policies(policies).items():
        rows = []
        for i in cells:
            t0 = time.time()
            spec = CellSpec(cells=(CELLS[i],), robots_per_cell=robots)  # evaluation physics
            env = cell_env(policy, spec)
            state = initial_states(env, spec)
            info = {k: v for k, v in state.info.items() if k != "final_obs"}
            tiles = np.asarray(info["tile"])
            batch = WarpBatch(env, np.asarray(state.pipeline_state.qpos))
            ep = gt.closed_loop(env, policy, info, batch, np.asarray(env.goals)[tiles],
                                np.zeros((len(tiles), 12), np.float32), env.episode_steps)
            r = cell_records(spec, ep.success, ep.fell, physics="mujoco_warp",
                             wall_s=time.time() - t0)
            rows.append(r)
            print(f"[warp] {name} cell {i} {CELLS[i]}: success {r['success'][0]:.3f} "
                  f"fell {r['fell'][0]:.3f} ({time.time() - t0:.0f} s)", flush=True)
            rec["policies"][name] = rows
            _write(out, rec)


def run_first(out: Path, robots: int, cells: list[int], policies: str | None) -> None:
    """The first second from the ground truth's states, its actions replayed in MuJoCo Warp."""
    from mjx_stairs.study import ground_truth as gt
    from mjx_stairs.study.evaluate import CellSpec, cell_env, initial_states

    def replay(policy, spec, start, actions):
        """As ground_truth.replay_in_mjx: positions, forces (not measured: NaN) and the
        episode ends by the evaluation's fall rule."""
        env = cell_env(policy, spec)
        state = initial_states(env, spec)
        goal = np.asarray(env.goals)[np.asarray(state.info["tile"])]
        qpos, qvel, _ = start
        batch = WarpBatch(env, qpos, qvel)
        c = env.config
        pos, done = [], []
        for a in actions:
            batch.step(rb.NOMINAL_JOINT_POS + c.robot.action_scale * a, c.decimation)
            pos.append(batch.qpos[:, :3])
            done.append(gt._endings(env, batch.qpos, batch.qvel, goal)[1])
        return np.array(pos), np.full((len(actions), qpos.shape[0]), np.nan), np.array(done)

    rec = {"policies": {}}
    for name, policy in _policies(policies).items():
        rec["policies"][name] = []
        for i in cells:
            spec = CellSpec(cells=(CELLS[i],), robots_per_cell=robots)  # evaluation physics
            r = gt.first_second(policy, spec, {}, replays={"warp": replay})
            rec["policies"][name].append(r)
            print(f"[first] {name} cell {i}: {r['options']['warp']['pos_error_at_horizon_mean_m']}"
                  " m", flush=True)
            _write(out, rec)


def _write(path: Path, record: dict) -> None:
    from mjx_stairs.atomic import write_text

    path.parent.mkdir(parents=True, exist_ok=True)
    write_text(path, json.dumps(record, indent=1))


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("what", choices=["rate", "success", "first"])
    p.add_argument("out", type=Path)
    p.add_argument("--robots", type=int, default=None)
    p.add_argument("--steps", type=int, default=20)
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--cells", default=None, help="indices into fidelity.CELLS")
    p.add_argument("--policies", default=None, help="names in fidelity.POLICIES")
    p.add_argument("--config", default="experiments/stage2_u.toml")
    p.add_argument("--env", action="append", default=["robot.physics=evaluation"])
    a = p.parse_args()
    if a.what == "rate":
        run_rate(a.out, a.robots or 4096, a.steps, a.repeats, a.config,
                 [f"env.{o}" for o in a.env])
    elif a.what == "success":
        cells = [int(c) for c in (a.cells or "8,9").split(",")]
        run_success(a.out, a.robots or 1000, cells, a.policies)
    else:
        cells = [int(c) for c in (a.cells or "3,8,15").split(",")]
        run_first(a.out, a.robots or 32, cells, a.policies)


if __name__ == "__main__":
    main()
