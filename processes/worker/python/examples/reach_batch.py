"""The MuJoCo arm of ``mujoco_reach.py`` as a vectorised simulator: a whole batch of reaches in
one call of ``mujoco.rollout``.

The planar two-link arm starts bent, its joint angles perturbed by each task's seed, and its
position actuators (kp 40, kv 4, forces within +-8) track joint-angle targets: ``theta[0:2]`` for
the first half of the movement, ``theta[2:4]`` for the second. Those targets are the whole
control signal, known before the movement starts, so MuJoCo's ``rollout`` module steps every
task of a batch in C. The context is the target (x, y) in metres; the return is minus the
squared distance of the hand to the target at the end, minus a small effort cost; the score is
that distance in centimetres. Every reach is independent of the others in its batch: one task
gives the same bits alone or among a thousand.

Through acps, with batch workers (``--batch``) or one rollout per call::

    acps run --config processes/worker/python/examples/reach_batch.toml \\
        --worker-command "python processes/worker/python/examples/reach_batch.py --batch"

and from your own loop with ``acps.Learner`` (python/examples/reach_ask_tell.py).
"""

from __future__ import annotations

import random
import sys
from typing import TYPE_CHECKING

import mujoco
import numpy as np
import numpy.typing as npt
from mujoco import rollout as mj_rollout

if TYPE_CHECKING:
    import acps_worker
    from acps_worker.batch import TaskBatch

Floats = npt.NDArray[np.float64]

ARM = """
<mujoco model="planar-arm-position">
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
    <position name="shoulder" joint="shoulder" kp="40" kv="4" forcerange="-8 8" forcelimited="true"/>
    <position name="elbow" joint="elbow" kp="40" kv="4" forcerange="-8 8" forcelimited="true"/>
  </actuator>
  <sensor>
    <framepos objtype="site" objname="hand"/>
    <actuatorfrc actuator="shoulder"/>
    <actuatorfrc actuator="elbow"/>
  </sensor>
</mujoco>
"""

# Everything that changes a rollout; reach_batch.toml states the same text.
SETTINGS = (
    "planar-arm position v1: dt 0.002 s, 0.6 s, kp 40, kv 4, force 8, effort 1e-4, "
    "start (0.5, 1.0) +- 0.02 rad"
)

DURATION = 0.6
EFFORT_WEIGHT = 1e-4
START = (0.5, 1.0)
START_NOISE = 0.02

model = mujoco.MjModel.from_xml_string(ARM)
data = mujoco.MjData(model)
STEPS = round(DURATION / model.opt.timestep)
STATE = mujoco.mjtState.mjSTATE_FULLPHYSICS
STATE_SIZE = mujoco.mj_stateSize(model, STATE)


def initial_states(seeds: npt.NDArray[np.uint64]) -> Floats:
    """The arm at rest, its joints perturbed by each seed: ``(n, STATE_SIZE)``."""
    states = np.empty((len(seeds), STATE_SIZE))
    for row, seed in enumerate(seeds):
        noise = random.Random(int(seed))
        mujoco.mj_resetData(model, data)
        for joint, angle in enumerate(START):
            data.qpos[joint] = angle + noise.gauss(0.0, START_NOISE)
        mujoco.mj_getState(model, data, states[row], STATE)
    return states


def reach(contexts: Floats, thetas: Floats, seeds: npt.NDArray[np.uint64]) -> tuple[Floats, Floats]:
    """Rewards and scores of reaching for ``contexts`` ``(n, 2)`` with the joint targets
    ``thetas`` ``(n, 4)`` from the starts of ``seeds`` ``(n,)``."""
    n = len(contexts)
    control = np.empty((n, STEPS, 2))
    control[:, : STEPS // 2] = thetas[:, None, 0:2]
    control[:, STEPS // 2 :] = thetas[:, None, 2:4]
    _, sensors = mj_rollout.rollout(model, data, initial_states(seeds), control)
    hand = sensors[:, -1, 0:2]
    forces = sensors[:, :, 3:5]
    effort = (forces * forces).sum(axis=(1, 2)) * model.opt.timestep
    distance = np.sqrt(((hand - contexts) ** 2).sum(axis=1))
    return -(distance**2) - EFFORT_WEIGHT * effort, 100.0 * distance


def batch_rollout(batch: TaskBatch) -> tuple[Floats, Floats]:
    """A batch worker's rollout: every task of ``batch`` in one ``reach``."""
    return reach(batch.contexts, batch.thetas, batch.seeds)


def rollout(task: acps_worker.Task) -> tuple[float, float]:
    """A per-task worker's rollout: ``reach`` of a batch of one (the same bits)."""
    rewards, scores = reach(
        np.array([task.context]), np.array([task.theta]), np.array([task.seed], dtype=np.uint64)
    )
    return float(rewards[0]), float(scores[0])


def main() -> None:
    """Serve the run named by $ACPS_RUN, by batches with ``--batch``, else task by task."""
    import acps_worker

    environment = acps_worker.Environment(name="mujoco-reach-batch", settings=SETTINGS)
    # Targets (x, y) and two joint-angle pairs: a problem of other sizes refuses this worker.
    sizes = (2, 4)
    if "--batch" in sys.argv[1:]:
        acps_worker.serve(
            batch_rollout=batch_rollout, environment=environment, sizes=sizes, queue_depth=32
        )
    else:
        acps_worker.serve(rollout, environment=environment, sizes=sizes)


if __name__ == "__main__":
    main()
