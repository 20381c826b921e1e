"""A digital twin: the whole real path (franky, RealSense, wall clock) with no hardware.

- :mod:`cablesim.twin.franka_sim`: a ``franka-sim`` server on 127.0.0.1 serving our Panda
  (the robot end; :class:`FrankaSimServer`).
- :mod:`cablesim.twin.world`: :class:`TwinWorld`, a cablesim world stepped in real time on its
  own thread whose Panda follows the robot's measured joints and gripper, rendering RGB-D;
  built from :mod:`~cablesim.twin.sources` (where the robot's state is read: franky or a
  replayed log), :mod:`~cablesim.twin.sampling` (the sampler threads and their time-stamped
  tracks), :mod:`~cablesim.twin.replay` (the measurements replayed on the twin's actuators)
  and :mod:`~cablesim.twin.state` (the published state, frames and statistics).
- :mod:`cablesim.twin.realsense`: :class:`SoftwareRealSense`, the twin's frames pushed live into
  a librealsense software device that ``RealSenseCamera`` reads.
- :mod:`cablesim.twin.truth`: :class:`TwinTruth`, the runner's ground-truth provider over the
  twin (labels by frame timestamp, grasp probe, follow gain, ground-truth flow).
- :mod:`cablesim.twin.episode`: :func:`twin_episode` wires them to the real runner and
  perception; :func:`sim_episode` runs the same seed in pure simulation.

The twin is simulation: it may import :mod:`cablesim.sim`; robot, camera, perception and
episode code never import it.
"""

from cablesim.twin.franka_sim import FrankaSimServer, FrankaSimUnavailable

__all__ = ["FrankaSimServer", "FrankaSimUnavailable"]
