"""The named outcomes of an interaction and of the runs that record one per seed or start.

    from cablesim.outcomes import Outcome
    result = session.interact(segment)
    if result.outcome is Outcome.UNREACHABLE: ...
    print(Outcome.GRASP_NOT_HELD.description)

An outcome is set where the failure is detected, never parsed from a message: a robot adapter
names the failures it can tell apart in :attr:`~cablesim.robot.base.MoveResult.outcome` (an
arm-model check that refuses a motion: ``UNREACHABLE``; a motion stopped on a contact in the
scene: ``COLLISION``), a primitive names its own (a grasp that does not hold:
``GRASP_NOT_HELD``) where the motion named none, and the interaction runner the rest (an
invalid segment, the robot in the target frame).  The simulated session names a scene that
could not serve (``SCENE_UNSETTLED``, ``NO_GRASPABLE_SEGMENT``) and a diverging physics
(``DIVERGED``): those are the ``outcome`` of the errors in :mod:`cablesim.errors`.

``Outcome`` is a ``str`` enum: a member is equal to its value (``Outcome.OK == "ok"``) and is
written as its value in JSON, in f-strings and by ``str()``, so result files read as before.
:func:`outcome_table` is the Markdown table of the docs (``docs/outcomes.md``).
"""

from __future__ import annotations

import enum


class Outcome(enum.StrEnum):
    """A named outcome; ``description`` says in one line what it means."""

    description: str

    OK = "ok", "the interaction ran; target frame captured"
    SEGMENT_INVALID = (
        "segment_invalid",
        "the segment is malformed or has too little depth under it",
    )
    UNREACHABLE = (
        "unreachable",
        "the grasp, its pre-grasp, an action end point or the path there is out of reach (IK, "
        "joint limits, a collision the arm model's check predicts)",
    )
    COLLISION = "collision", "a motion stopped on a contact in the scene (board, table, a coupling)"
    GRASP_NOT_HELD = (
        "grasp_not_held",
        "the fingers closed on nothing or the hose slipped, after every retry; with ground truth "
        "also a grasped hose that did not follow the hand during an action",
    )
    ACTION_FAILED = (
        "action_failed",
        "an action stroke ended off its target (the hose held the hand back)",
    )
    RELEASE_FAILED = "release_failed", "the gripper did not open"
    RETREAT_FAILED = "retreat_failed", "the arm could not move out of view"
    ROBOT_IN_VIEW = "robot_in_view", "the robot is visible in the target frame"
    # simulation: the scene before any interaction (see cablesim.sim.session)
    SCENE_ERROR = (
        "scene_error",
        "the simulated scene cannot serve the experiment (cablesim.errors.SceneError; its "
        "kinds below name themselves)",
    )
    SCENE_UNSETTLED = (
        "scene_unsettled",
        "no scene draw settled (cablesim.errors.SceneUnsettledError)",
    )
    NO_GRASPABLE_SEGMENT = (
        "no_graspable_segment",
        "no scene draw had a hose of interest with a graspable segment",
    )
    DIVERGED = (
        "diverged",
        "the physics diverged (cablesim.errors.PhysicsDivergedError): NaN, a MuJoCo warning, or "
        "a hose edge stretched past physics.max_hose_strain",
    )

    def __new__(cls, value: str, description: str) -> Outcome:
        member = str.__new__(cls, value)
        member._value_ = value
        member.description = description
        return member


#: value -> description of every outcome (the table of :func:`outcome_table` as a mapping)
OUTCOMES: dict[str, str] = {o.value: o.description for o in Outcome}


def worst(*outcomes: Outcome | None) -> Outcome | None:
    """The outcome of a motion made of several (a blocked joint path, then the way round):
    a collision in the scene before a refused plan before none."""
    for kind in (Outcome.COLLISION, Outcome.UNREACHABLE):
        if kind in outcomes:
            return kind
    return next((o for o in outcomes if o is not None), None)


def outcome_table() -> str:
    """A Markdown table of every outcome: its name in Python, its value (what result files
    hold) and its description."""
    lines = ["| outcome | value | meaning |", "| --- | --- | --- |"]
    for o in Outcome:
        lines.append(f"| `Outcome.{o.name}` | `{o.value}` | {o.description} |")
    return "\n".join(lines) + "\n"


__all__ = ["OUTCOMES", "Outcome", "outcome_table", "worst"]
