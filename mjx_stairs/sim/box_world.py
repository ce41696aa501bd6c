"""The Go2 on a box staircase in MuJoCo itself: the ground truth our MJX physics is checked against.

Nothing of the fast path computes it: no heightfield, no MJX, no collider of ours. The staircase
is `terrains.boxes` (vertical risers, sharp edges), the solver is MuJoCo's default (Newton, 100
iterations, 50 line-search steps, tolerance 1e-8) on the CPU (`mujoco.mj_step`), and the robot is
the same MJCF (assets/go2.xml: same bodies, collision spheres, contact parameters, 5 ms Euler
step) with the same PD law: clip(kp (q* - q) - kd qd, -limit, limit) at every physics step. The PD
runs inside MuJoCo as one affine actuator per joint (force = kp ctrl - kp q - kd qd, clamped to the
torque limit), with ctrl = q*, so that many robots step in C threads (`mujoco.rollout`) with the
policy's target held over the `decimation` substeps, exactly as the env holds it.
"""

from __future__ import annotations

import dataclasses
import os

import mujoco
import numpy as np
from mujoco import rollout

from mjx_stairs.sim import robot as rb

STATE = mujoco.mjtState.mjSTATE_FULLPHYSICS
"""What a rollout carries from one policy step to the next: time, qpos, qvel, act, ... ."""


@dataclasses.dataclass(frozen=True)
class SolverConfig:
    """MuJoCo's own defaults, not the fast path's 1 Newton iteration."""

    iterations: int = 100
    ls_iterations: int = 50
    tolerance: float = 1e-8


DEFAULT_SOLVER = SolverConfig()


def build_model(
    boxes: np.ndarray,
    config: rb.RobotConfig | None = None,
    solver: SolverConfig | None = None,
    heightfield: tuple[np.ndarray, float] | None = None,
) -> mujoco.MjModel:
    """The Go2 standing among `boxes` [M, 6] (cx, cy, cz, hx, hy, hz), PD as actuators.

    Collision spheres are spheres whatever `config.terrain_contacts` says; mid-shin spheres
    collide when `config.shin_collision`, the head and the calf and thigh chains (capsules with
    `config.limb_capsules`) are there when `config.head_collision`, `config.calf_collision` and
    `config.thigh_collision` say so.
    Gains are `config.kp` / `config.kd`, limits the reference torque limits times
    `config.torque_scale`, the joints' passive damping `config.joint_damping` (None: the MJCF's).
    `heightfield` = (heights, resolution) stands the robot on that heightfield instead (MuJoCo's
    own heightfield collider, the terrain shape MJX sees: for telling the terrain's shape from
    MJX's solver and collider).
    """
    config = config or rb.RobotConfig()
    solver = solver or DEFAULT_SOLVER
    spec = mujoco.MjSpec.from_file(str(rb.ASSET))
    spec.option.timestep = config.timestep
    spec.option.iterations = solver.iterations
    spec.option.ls_iterations = solver.ls_iterations
    spec.option.tolerance = solver.tolerance
    if heightfield is not None:
        rb.add_heightfield(spec, np.asarray(heightfield[0], np.float32), heightfield[1],
                           config.friction)
    for i, (cx, cy, cz, hx, hy, hz) in enumerate(np.asarray(boxes, np.float64)):
        spec.worldbody.add_geom(
            name=f"stair{i}",
            type=mujoco.mjtGeom.mjGEOM_BOX,
            pos=[cx, cy, cz],
            size=[hx, hy, hz],
            contype=0,
            conaffinity=1,
            material="terrain",
            friction=[config.friction, 0.02, 0.01],
        )
    rb.apply_robot_settings(spec, config)
    _pd_actuators(spec, config)
    model = spec.compile()
    order = [model.actuator(i).trnid[0] for i in range(model.nu)]
    if order != [model.joint(n).id for n in rb.JOINT_NAMES]:
        raise ValueError("go2.xml's actuators are not in JOINT_NAMES order")
    return model


def _pd_actuators(spec: mujoco.MjSpec, config: rb.RobotConfig) -> None:
    """Each joint's actuator as PD on its target (`config.kp` / `config.delayed_kd`: kd at the
    robot's action delay), its force clamped at the reference torque limit times
    `config.torque_scale`."""
    limits = rb.TORQUE_LIMIT * config.torque_scale
    for joint, limit in zip(rb.JOINT_NAMES, limits, strict=True):
        act = next(a for a in spec.actuators if a.target == joint)
        act.gaintype = mujoco.mjtGain.mjGAIN_FIXED
        act.gainprm[0] = config.kp
        act.biastype = mujoco.mjtBias.mjBIAS_AFFINE
        act.biasprm[:3] = [0.0, -config.kp, -config.delayed_kd]
        act.forcelimited = True
        act.forcerange = [-float(limit), float(limit)]


class Batch:
    """N robots on box models (one per robot, shared where robots share a staircase), stepped
    together in C threads.

    `qpos` [N, 19] and `qvel` [N, 18] are the robots' state after the last `step`.
    """

    def __init__(self, models: list[mujoco.MjModel], qpos: np.ndarray,
                 qvel: np.ndarray | None = None, nthread: int | None = None):
        self.nthread = nthread or os.cpu_count() or 1
        self.models = models
        m0 = models[0]
        self.nq, self.nv = m0.nq, m0.nv
        # mujoco.rollout wants models of one size signature per call: robots grouped by model,
        # each group with one MjData per thread.
        self._groups: dict[int, list[int]] = {}
        for i, m in enumerate(models):
            self._groups.setdefault(id(m), []).append(i)
        self._datas = {k: [mujoco.MjData(models[rows[0]]) for _ in range(self.nthread)]
                       for k, rows in self._groups.items()}
        self.state = np.zeros((len(models), mujoco.mj_stateSize(m0, STATE)))
        velocities = np.zeros((len(models), m0.nv)) if qvel is None else qvel
        for i, m in enumerate(models):
            d = self._datas[id(m)][0]
            d.qpos[:] = qpos[i]
            d.qvel[:] = velocities[i]
            mujoco.mj_forward(m, d)
            mujoco.mj_getState(m, d, self.state[i], STATE)
        self._runner = rollout.Rollout(nthread=self.nthread)

    @property
    def qpos(self) -> np.ndarray:
        return self.state[:, 1 : 1 + self.nq]

    @property
    def qvel(self) -> np.ndarray:
        return self.state[:, 1 + self.nq : 1 + self.nq + self.nv]

    def step(self, q_target: np.ndarray, substeps: int, active: np.ndarray | None = None,
             previous: np.ndarray | None = None, delay: int = 0) -> None:
        """Hold PD targets `q_target` [N, 12] for `substeps` physics steps, the first `delay` of
        them still `previous` [N, 12] (an action delay, as the env's); robots not `active` stay
        as they are."""
        on = np.ones(len(self.models), bool) if active is None else np.asarray(active, bool)
        target = np.asarray(q_target, np.float64)
        for key, group in self._groups.items():
            rows = np.array([i for i in group if on[i]], np.int64)
            if rows.size == 0:
                continue
            ctrl = np.repeat(target[rows, None, :], substeps, axis=1)
            if delay > 0:
                ctrl[:, :delay] = np.asarray(previous, np.float64)[rows, None, :]
            state, _ = self._runner.rollout(
                self.models[rows[0]], self._datas[key], self.state[rows], ctrl, nstep=substeps
            )
            self.state[rows] = state[:, -1]

    def close(self) -> None:
        self._runner.close()


def contact_summary(model: mujoco.MjModel, data: mujoco.MjData) -> dict[str, float]:
    """Terrain contact of one robot now: |net vertical force| (N) and the number of contacts."""
    f6 = np.zeros(6)
    net = np.zeros(3)
    for i in range(data.ncon):
        mujoco.mj_contactForce(model, data, i, f6)
        net += data.contact.frame[i].reshape(3, 3).T @ f6[:3]
    return {"vertical_force": abs(net[2]), "ncon": float(data.ncon)}
