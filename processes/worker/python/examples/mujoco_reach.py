"""A MuJoCo arm learns to reach any target in its workspace, through acps.

A planar two-link arm (MuJoCo, CPU only, no rendering) starts bent, with its joint angles
perturbed by the task's seed, and moves under PD control towards joint-angle targets: the first
half of the movement towards ``theta[0:2]``, the second towards ``theta[2:4]``. The context is the
target (x, y) in metres; the return is minus the squared distance of the hand to the target at
the end, minus a small effort cost; the score is that distance in centimetres. acps learns one
policy theta(s) for every target of the workspace.

Run it through acps (README, "Your own simulator in Python")::

    acps run --config processes/worker/python/examples/mujoco_reach.toml \\
        --worker-command "python processes/worker/python/examples/mujoco_reach.py"
"""

from __future__ import annotations

import math
import random
from collections.abc import Sequence

import mujoco

import acps_worker

ARM = """
<mujoco model="planar-arm">
  <option timestep="0.002" gravity="0 0 0" integrator="implicitfast"/>
  <worldbody>
    <body name="upper">
      <joint name="shoulder" type="hinge" axis="0 0 1" damping="0.05"/>
      <geom type="capsule" fromto="0 0 0 0.5 0 0" size="0.03" mass="1"/>
      <body name="fore" pos="0.5 0 0">
        <joint name="elbow" type="hinge" axis="0 0 1" damping="0.05"/>
        <geom type="capsule" fromto="0 0 0 0.4 0 0" size="0.025" mass="0.6"/>
        <site name="hand" pos="0.4 0 0"/>
      </body>
    </body>
  </worldbody>
  <actuator>
    <motor joint="shoulder" ctrlrange="-8 8" ctrllimited="true"/>
    <motor joint="elbow" ctrlrange="-8 8" ctrllimited="true"/>
  </actuator>
</mujoco>
"""

# Everything that changes a rollout; the problem file states the same text, so a worker with
# another arm or controller is refused instead of mixed in.
SETTINGS = (
    "planar-arm v1: dt 0.002 s, 0.6 s, kp 40, kd 4, effort 1e-4, start (0.5, 1.0) +- 0.02 rad"
)
ENVIRONMENT = acps_worker.Environment(name="mujoco-reach", settings=SETTINGS)

DURATION = 0.6
KP, KD = 40.0, 4.0
EFFORT_WEIGHT = 1e-4
START = (0.5, 1.0)
START_NOISE = 0.02

model = mujoco.MjModel.from_xml_string(ARM)
data = mujoco.MjData(model)
hand = model.site("hand").id


def rollout(task: acps_worker.Task) -> tuple[float, float]:
    """Reach for ``task.context`` with the joint targets ``task.theta``."""
    target_x, target_y = task.context
    theta: Sequence[float] = task.theta
    noise = random.Random(task.seed)
    mujoco.mj_resetData(model, data)
    for joint, angle in enumerate(START):
        data.qpos[joint] = angle + noise.gauss(0.0, START_NOISE)
    steps = round(DURATION / model.opt.timestep)
    effort = 0.0
    for step in range(steps):
        goal = theta[0:2] if step < steps // 2 else theta[2:4]
        for joint in range(2):
            data.ctrl[joint] = KP * (goal[joint] - data.qpos[joint]) - KD * data.qvel[joint]
        mujoco.mj_step(model, data)
        effort += float(data.ctrl[0] ** 2 + data.ctrl[1] ** 2) * model.opt.timestep
    x, y = data.site_xpos[hand][0], data.site_xpos[hand][1]
    distance = math.hypot(x - target_x, y - target_y)
    return -(distance**2) - EFFORT_WEIGHT * effort, 100.0 * distance


if __name__ == "__main__":
    acps_worker.serve(rollout=rollout, environment=ENVIRONMENT)
