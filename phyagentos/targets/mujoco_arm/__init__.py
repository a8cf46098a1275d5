"""One base for every simulated MuJoCo arm: scene, sensors, rendering, checkpoints, truth.

:class:`MuJoCoArmTarget` holds what the Franka tabletop
(:class:`~phyagentos.targets.franka_tabletop.MuJoCoTarget`), the SO-101
(:class:`~phyagentos.targets.so101.SO101Target`) and FrankaKitchen
(:class:`~phyagentos.targets.kitchen.FrankaKitchenTarget`) have in common:

- joint bookkeeping (``arm_qpos``, ``tcp_pose``, trajectory validation, hold, halt);
- the tabletop scene's world model (entities and relations of a
  :class:`~phyagentos.targets.scene.SceneSpec`) and the finger-contact bookkeeping;
- sensors: :meth:`capture` renders an RGB-D :class:`~phyagentos.perception.frames.CameraFrame`
  from a model camera with intrinsics from its ``fovy`` and seeded camera noise;
  :meth:`proprioception` reads joints, actuator forces, the gripper and the wrist
  force-torque sensor;
- checkpoints (:meth:`save_state` / :meth:`load_state`, atomic npz with a model fingerprint);
- the privileged ground-truth channel :meth:`ground_truth` (true poses, sizes, masses,
  frictions, contacts), read only by benchmark scoring and tests (CONTRACT_9 section 2).

Units: metres, radians, seconds, kilograms, newtons; poses are (4, 4) world transforms.
"""

from phyagentos.geometry import matrix_to_quat as mat_quat
from phyagentos.geometry import pose_matrix

from .common import K_ENV, K_FINGER, K_NONE, K_OBJECT, K_ROBOT
from .core import GripperResult, MuJoCoArmTarget, PlansOnTheTabletop

__all__ = ["MuJoCoArmTarget", "GripperResult", "PlansOnTheTabletop", "pose_matrix", "mat_quat", "K_NONE", "K_ENV",
           "K_ROBOT", "K_FINGER", "K_OBJECT"]
