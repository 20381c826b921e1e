"""The arm model the digital twin's ``franka-sim`` server simulates: our Panda as MJCF.

:func:`franka_sim_mjcf` writes it (:class:`~cablesim.twin.franka_sim.FrankaSimServer` hands it
to the server); :data:`FRANKA_SIM_ARMATURE` is the joint armature that keeps the server's servo
stable on it.  The real robot's adapter (:mod:`cablesim.robot.franky_panda`) never needs it.
"""

from __future__ import annotations

import numpy as np

from cablesim.panda.description import HAND_OFFSET
from cablesim.panda.model import panda_spec
from cablesim.pose import quat_to_mat

#: Armature (reflected rotor inertia, kg m^2) of each arm joint in the franka-sim server's model
#: (see :func:`franka_sim_mjcf`).
FRANKA_SIM_ARMATURE = 0.5


def franka_sim_mjcf() -> str:
    """MJCF of our Panda for the ``franka-sim`` server (its ``$FR3_MJCF``), as an XML string.

    franka-sim reports the pose of the body ``link7`` (composed with ``F_T_EE``) as ``O_T_EE``,
    i.e. it treats ``link7`` as the flange.  Here ``link7``'s frame is moved to the flange
    (``HAND_OFFSET`` further along its joint axis, the joint and geoms shifted back) so the
    kinematics are unchanged and ``O_T_EE`` means what it means on the real robot.  The fingers,
    tendon, equalities and actuators are removed: the server simulates the arm and runs its own
    gripper model.  Each link's largest geom is named ``link{N}_collision``, which arms the
    server's self-collision reflex (with ``enforce_motion_limits``).  MuJoCo >= 3.2 reads it.
    """

    spec = panda_spec(home_key=False)
    hand = spec.body("hand")
    for name in ("left_finger", "right_finger"):
        spec.delete(spec.body(name))
    for collection in (spec.equalities, spec.tendons, spec.actuators):
        for element in list(collection):
            spec.delete(element)
    hand.mass += 0.03  # the two fingers
    link7 = spec.body("link7")
    shift = np.array([0.0, 0.0, HAND_OFFSET])
    quat = np.asarray(link7.quat, dtype=float)
    R = quat_to_mat(quat / np.linalg.norm(quat))
    link7.pos = (np.asarray(link7.pos) + R @ shift).tolist()
    link7.ipos = (np.asarray(link7.ipos) - shift).tolist()
    for joint in link7.joints:
        joint.pos = (np.asarray(joint.pos) - shift).tolist()
    for geom in link7.geoms:
        fromto = np.asarray(geom.fromto, dtype=float)
        if np.all(np.isfinite(fromto)) and np.any(fromto != 0.0):
            geom.fromto = (fromto - np.concatenate([shift, shift])).tolist()
        else:
            geom.pos = (np.asarray(geom.pos) - shift).tolist()
    for site in link7.sites:
        site.pos = (np.asarray(site.pos) - shift).tolist()
    hand.pos = (np.asarray(hand.pos) - shift).tolist()
    # franka-sim servoes the arm explicitly (``qfrc_applied = KP e + KD (dq_c - dq)``, KD 200-450
    # Nm s/rad) at its 1 ms step, which is stable only while dt * max eig(M^-1 KD) < 2.  With
    # the Menagerie's 0.1 kg m^2 armature that is 3.37 at q2 = 0 (joints 1 and 3 aligned, the
    # twin's stance) and 1.88 at the ready pose: joints 1 and 3 chatter against each other at
    # the 87 Nm torque limit, the arm overshoots a finished 10 cm/s stroke and the hold drifts
    # up to 15 mm off its target (benchmarks/results/franka_sim_timing.md).  At
    # FRANKA_SIM_ARMATURE it is 0.77 and 0.58: damped without oscillation.
    for joint in spec.joints:
        if joint.name.startswith("joint"):
            joint.armature = FRANKA_SIM_ARMATURE
    # franka-sim's self-collision reflex watches one geom per link, ``link{N}_collision``:
    # give that name to each link's largest geom.
    model = spec.compile()
    for n in range(8):
        body = model.body(f"link{n}").id
        geoms = np.flatnonzero(model.geom_bodyid == body)
        largest = int(geoms[np.argmax(model.geom_rbound[geoms])])
        spec.geom(model.geom(largest).name).name = f"link{n}_collision"
    spec.compile()
    return spec.to_xml()
