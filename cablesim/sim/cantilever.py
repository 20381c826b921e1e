"""How far a cable of a kind bends under its own weight: the cantilever test of a bending
stiffness, on the same MuJoCo rod the scenes are built of.

    sag = cantilever_sag(cable_kind("rope"))       # m the free end drops below the clamp

A ``length`` of the cable is clamped level at one end (its first two vertices pinned, which
fixes the tangent) and left to settle under gravity; the sag is how far its free end ends up
below the clamp.  An elastic rod of bending stiffness ``EI`` and weight ``w`` per metre sags
``w L^4 / (8 EI)`` while that is small against ``L`` (the Euler-Bernoulli cantilever), and
towards ``L`` (hanging straight down) when ``EI`` is small against ``w L^3``: the comparison
a user makes when holding a cable out level.  ``docs/cables.md`` tabulates it per kind.
"""

from __future__ import annotations

import math

import mujoco
import numpy as np

from cablesim.cables import CableKind
from cablesim.errors import PhysicsDivergedError
from cablesim.sim.world import cable_xml, compensate_weight, damp_cable_dofs


def cantilever_sag(
    cable: CableKind,
    young: float | None = None,
    length: float = 0.3,
    time: float = 4.0,
    timestep: float = 0.004,
) -> float:
    """Metres the free end of a level-clamped ``length`` of ``cable`` drops after ``time``
    seconds (``young``: the rod's modulus, default the geometric mean of the kind's range)."""
    if young is None:
        young = math.sqrt(cable.young[0] * cable.young[1])
    n = max(8, int(round(length / cable.segment_length)) + 1)
    spacing = length / (n - 1)
    centre = np.array([length / 2, 0.0, 1.0])
    xml = f"""
<mujoco model="cantilever">
  <option timestep="{timestep!r}" integrator="discrete" solver="Newton"/>
  <worldbody>
    {
        cable_xml(
            "cable",
            cable,
            young,
            n,
            spacing,
            centre,
            "1 0 0 0",
            cable.colors[0],
            cable.mass_per_metre * length * cable.inertia_scale,
            inner='<pin id="0 1"/>',
        )
    }
  </worldbody>
</mujoco>"""
    spec = mujoco.MjSpec.from_string(xml)
    compensate_weight(spec, "cable", cable)  # as the scenes: the kind's weight, its inertia
    model = spec.compile()
    data = mujoco.MjData(model)
    damp_cable_dofs(model, range(model.njnt), cable)  # the scenes' per-dof damping
    mujoco.mj_step(model, data, nstep=int(round(time / timestep)))
    verts = data.flexvert_xpos
    if not np.isfinite(verts).all():
        raise PhysicsDivergedError(f"the {cable.name} cantilever diverged")
    return float(centre[2] - verts[-1, 2])
