"""A single moving hose: every other hose held exactly still (MovingCables, thesis chapter 5).

    freeze = HoseFreeze(world, moving=2)      # a world step hook
    world.after_step.append(freeze)           # for the rest of the session
    ...
    freeze.release()                          # contacts back as they were; remove the hook

The MovingCables clips show one moving hose over still ones (composited layers in the real
dataset, so the hoses never push each other).  ``HoseFreeze`` does the same in simulation: the
moving hose no longer touches the other hoses (flex collision filtering: the others get their
own contact bits), and after every physics step the other hoses' vertex and twist joints are
put back to where they were when the hook was made, with zero velocity, so they do not move by
a single bit.  The robot and the board still touch the moving hose as before.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from cablesim.errors import InputError

FROZEN_BITS = 2  # contype/conaffinity of the still hoses: nothing else has this bit


class HoseFreeze:
    """See the module docstring."""

    def __init__(self, world: Any, moving: int) -> None:
        n = len(world.hoses)
        if isinstance(moving, bool) or not isinstance(moving, int) or not 0 <= moving < n:
            raise InputError(f"moving must be one of the {n} hoses, got {moving!r}")
        m = world.model
        self.world, self.moving = world, moving
        qpos, dofs = [], []
        frozen = [h for i, h in enumerate(world.hoses) if i != moving]
        names = tuple(h.spec.name for h in frozen)
        for b in range(m.nbody):
            name = m.body(b).name
            if not any(name.startswith(p + "_") for p in names):
                continue
            for j in range(m.body_jntadr[b], m.body_jntadr[b] + m.body_jntnum[b]):
                qpos.append(m.jnt_qposadr[j])
                dofs.append(m.jnt_dofadr[j])
        self.qpos_idx = np.array(qpos, np.int64)
        self.dof_idx = np.array(dofs, np.int64)
        self.q0 = world.data.qpos[self.qpos_idx].copy()
        flex = np.array([h.flex_id for h in frozen], np.int64)
        self._flex = flex
        self._saved = (m.flex_contype[flex].copy(), m.flex_conaffinity[flex].copy())
        m.flex_contype[flex] = FROZEN_BITS
        m.flex_conaffinity[flex] = FROZEN_BITS

    def __call__(self, world: Any) -> None:
        d = world.data
        d.qpos[self.qpos_idx] = self.q0
        d.qvel[self.dof_idx] = 0.0

    def release(self) -> None:
        """Restore the contact bits and remove the hook from the world (if installed)."""
        m = self.world.model
        m.flex_contype[self._flex], m.flex_conaffinity[self._flex] = self._saved
        if self in self.world.after_step:
            self.world.after_step.remove(self)
