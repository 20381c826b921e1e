"""What holds the cables, as an interaction needs to know it (simulated or real): the
direction in which the hand approaches a grasp, the plane the actions move in, and the height
of a horizontal surface under the grasp, which the fingertips must stay above.

    BOARD  # cables hanging in front of a vertical board: approach +x, actions in the image plane
    TABLE  # cables lying on the table: approach from above, actions in the table's plane

A simulated world gives its own (``World.surface``, from ``SceneConfig.surface``); a real
session the board's unless told otherwise.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: How far the Panda's fingertips reach past the TCP along the hand's approach axis (m).
FINGERTIP_REACH = 0.0095
#: The gap (m) kept between the fingertips and a surface under the grasp (``Surface.clearance``
#: unless a surface says otherwise).
FINGERTIP_CLEARANCE = 0.0005


@dataclass(frozen=True)
class Surface:
    """``approach``: the hand's approach direction (world, towards the surface); ``in_plane``:
    the actions ``along`` and ``across`` move in the surface's plane (normal ``-approach``)
    rather than in the image plane (on the board the two nearly agree, and the image plane is
    what the thesis used); ``height``: the world z of a horizontal surface under the grasp
    (None: none), which raises a grasp so that the fingertips stay ``clearance`` above it (the
    table's 0: they come down onto the mat, whose simulated contact lets the finger pads in,
    ``cablesim.sim.world.YIELDING_BITS``); ``lift``: how far the hand lifts the grasped cable
    off the surface (along -approach) before the actions, so that the fingertips do not drag on
    it (measured on the table without it: the pads' friction on the mat held the hand 16 mm
    short of an action's target); ``faces_camera``: the surface lies behind the cables along the
    camera's view, so the nearest depths of a proposed segment are the cable's (the board; the
    exploration's ``front_filter`` relies on it), not the table seen obliquely, where depth runs
    along a lying cable; ``needs_slack``: the cables lie on the surface, held along their length
    by friction, so a grasp needs slack between it and each plugged end
    (:func:`cablesim.sim.picker.slack_to_plugged_ends`)."""

    name: str
    approach: tuple[float, float, float]
    # two unit world axes spanning the surface's plane (e.g. the neighbour perturbation's)
    plane: tuple[tuple[float, float, float], tuple[float, float, float]]
    in_plane: bool = False
    height: float | None = None
    lift: float = 0.0
    faces_camera: bool = False
    needs_slack: bool = False
    clearance: float = FINGERTIP_CLEARANCE

    def grasp_centre(self, centre: np.ndarray) -> np.ndarray:
        """``centre`` (world), raised where the fingertips would otherwise touch the surface."""
        c = np.array(centre, float)
        if self.height is not None:
            c[2] = max(c[2], self.height + FINGERTIP_REACH + self.clearance)
        return c


BOARD = Surface("board", (1.0, 0.0, 0.0), ((0.0, 1.0, 0.0), (0.0, 0.0, 1.0)), faces_camera=True)
#: the table's top lies at z = 0, the simulated mat's at 0.5 mm (cablesim.sim.table.MAT_TOP)
TABLE = Surface(
    "table",
    (0.0, 0.0, -1.0),
    ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0)),
    in_plane=True,
    height=0.0005,
    lift=0.01,
    needs_slack=True,
    clearance=0.0,
)
SURFACES = {s.name: s for s in (BOARD, TABLE)}
