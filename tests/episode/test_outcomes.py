"""Typed outcomes (issue 20): each failure is named where it is detected (the robot's motion,
the primitive, the runner's phase), never parsed from its message; the docs' table is the
code's; the interaction runs as its phases over one state."""

from __future__ import annotations

import dataclasses
import json
import re
from pathlib import Path

import numpy as np
import pytest

from cablesim.camera.base import Camera, CameraImage
from cablesim.episode import primitives as prim
from cablesim.episode.clock import PlanningClock
from cablesim.episode.config import ActionConfig, GraspConfig, InteractionConfig
from cablesim.episode.runner import (
    PHASES,
    InteractionOptions,
    InteractionResult,
    InteractionState,
    run_interaction,
)
from cablesim.errors import (
    NoGraspableSegmentError,
    PhysicsDivergedError,
    SceneError,
    SceneUnsettledError,
)
from cablesim.frames import Intrinsics
from cablesim.outcomes import OUTCOMES, Outcome, outcome_table, worst
from cablesim.panda.description import HOME_QPOS
from cablesim.pose import Pose
from cablesim.robot.base import MoveResult, Robot

DOCS = Path(__file__).resolve().parents[2] / "docs" / "outcomes.md"
W, H = 64, 48
APPROACH_SPEED, STROKE_SPEED = 0.05, 0.04  # how the fake robot tells an approach from a stroke
PARK = (0.5, -0.5, 0.0, -2.0, 0.0, 1.6, 0.8)


# ---------------------------------------------------------------------- the table
def test_docs_table_is_the_one_outcome_table_generates() -> None:
    text = DOCS.read_text(encoding="utf-8")
    section = text.split("\n## Every outcome\n", 1)[1].split("\n## ", 1)[0]
    table = "".join(ln + "\n" for ln in section.splitlines() if ln.startswith("|"))
    assert table == outcome_table()
    assert "outcome_table()" in text  # the page says where its table comes from


def test_every_outcome_has_a_value_and_a_one_line_description() -> None:
    values = [o.value for o in Outcome]
    assert len(set(values)) == len(values)
    for o in Outcome:
        assert re.fullmatch(r"[a-z]+(_[a-z]+)*", o.value), o
        assert o.description and "\n" not in o.description, o
        assert f"| `Outcome.{o.name}` | `{o.value}` | {o.description} |" in outcome_table()
    assert OUTCOMES == {o.value: o.description for o in Outcome}


def test_an_outcome_is_written_as_its_value() -> None:
    res = InteractionResult(False, reason="r", outcome=Outcome.GRASP_NOT_HELD)
    assert json.loads(json.dumps(res.to_dict()))["outcome"] == "grasp_not_held"
    assert json.dumps({"o": Outcome.OK}) == '{"o": "ok"}'
    assert f"{Outcome.COLLISION}" == str(Outcome.COLLISION) == "collision"
    assert Outcome("unreachable") is Outcome.UNREACHABLE and Outcome.OK == "ok"
    assert "FAILED (grasp_not_held)" in res.summary()


def test_the_errors_carry_their_outcomes() -> None:
    assert PhysicsDivergedError.outcome is Outcome.DIVERGED
    assert SceneError.outcome is Outcome.SCENE_ERROR
    assert SceneUnsettledError("x").outcome is Outcome.SCENE_UNSETTLED
    assert NoGraspableSegmentError("x").outcome is Outcome.NO_GRASPABLE_SEGMENT


def test_worst_of_a_motion_made_of_two() -> None:
    assert worst(Outcome.UNREACHABLE, Outcome.COLLISION) is Outcome.COLLISION
    assert worst(None, Outcome.UNREACHABLE) is Outcome.UNREACHABLE
    assert worst(None, None) is None


# ---------------------------------------------------------------------- fakes
class _Board(Camera):
    """A flat board 1 m in front of a camera that looks along world +x (the board normal is
    -x, as in the scene)."""

    T = np.array([[0, 0, 1, 0], [-1, 0, 0, 0], [0, -1, 0, 1.0], [0, 0, 0, 1]], float)

    @property
    def intrinsics(self) -> Intrinsics:
        return Intrinsics(500.0, 500.0, W / 2, H / 2, W, H)

    @property
    def T_world_camera(self) -> np.ndarray:
        return self.T

    def capture(self) -> CameraImage:
        return CameraImage(
            np.zeros((H, W, 3), np.uint8), np.ones((H, W), np.float32), 0.0, self.intrinsics
        )


class _Arm(Robot):
    """Reaches every pose and grasps at once; ``failures(kind, speed_or_q)`` scripts the motion
    that fails (a MoveResult) or None.  Every motion is logged."""

    def __init__(self, failures=None, held: bool = True) -> None:
        self.T_world_camera = _Board.T
        self.failures = failures or (lambda kind, arg: None)
        self.held = held
        self.log: list[tuple[str, object]] = []
        self._pose = Pose(np.array([0.3, 0.0, 0.5]))
        self._q = np.asarray(HOME_QPOS, float)

    def ee_pose(self) -> Pose:
        return self._pose

    @property
    def gripper_opening(self) -> float:
        return 0.08

    @property
    def joint_positions(self) -> np.ndarray:
        return self._q.copy()

    def move_to(self, pose: Pose, speed: float = 0.1, angular_speed: float = 0.8) -> MoveResult:
        self.log.append(("move_to", speed))
        r = self.failures("move_to", speed)
        if r is None:
            self._pose = pose
            return MoveResult(True, "", 0.0)
        return r

    def move_joints(self, q: np.ndarray, speed_factor: float = 0.3) -> MoveResult:
        q = tuple(np.round(np.asarray(q, float), 6))
        self.log.append(("move_joints", q))
        r = self.failures("move_joints", q)
        if r is None:
            self._q = np.asarray(q)
            return MoveResult(True)
        return r

    def solve_ik(self, pose: Pose) -> np.ndarray | None:
        return np.asarray(HOME_QPOS, float)

    def check_reachable(self, pose: Pose) -> tuple[bool, str]:
        return True, ""

    def open(self, width: float = 0.08, speed: float = 0.1) -> bool:
        self.log.append(("open", width))
        return True

    def grasp(self, width=0.015, force=70.0, speed=0.05, epsilon_inner=0.01, epsilon_outer=0.01):
        self.log.append(("grasp", width))
        return self.held


def _config(kind: str = "grasp") -> InteractionConfig:
    return InteractionConfig(
        kind=kind,
        grasp=GraspConfig(retries=0, approach_speed=APPROACH_SPEED),
        actions=ActionConfig(periods=1, speed=STROKE_SPEED),
    )


def _segment() -> np.ndarray:
    mask = np.zeros((H, W), bool)
    mask[H // 2, 20:44] = True  # a horizontal hose on the board
    return mask


def _run(arm: _Arm, kind: str = "grasp", segment=None) -> InteractionResult:
    cam = _Board()
    return run_interaction(
        arm,
        cam,
        PlanningClock(cam),
        _segment() if segment is None else segment,
        _config(kind),
        options=InteractionOptions(park=PARK),
    )


def _fails(kind: str, when, reason: str, outcome: Outcome | None):
    return lambda k, arg: (
        MoveResult(False, reason, 0.05, outcome=outcome) if k == kind and when(arg) else None
    )


def _parked(arm: _Arm) -> bool:
    return ("move_joints", tuple(np.round(PARK, 6))) in arm.log


# ---------------------------------------------------------------------- the runner
def test_an_interaction_that_runs_through_is_ok() -> None:
    arm = _Arm()
    res = _run(arm)
    assert res.success and res.outcome is Outcome.OK, res.reason
    assert res.stream is not None and len(res.stream) == 1  # no ticks in a dry run: the target
    assert [a.label for a in res.actions] == ["along", "across"]
    strokes = [e for e in arm.log if e == ("move_to", STROKE_SPEED)]
    assert len(strokes) == 8  # two actions of one period: four strokes each
    assert arm.log[-1] == ("move_joints", tuple(np.round(PARK, 6)))


def test_a_collision_named_by_the_robot_is_the_outcome_and_the_arm_leaves() -> None:
    arm = _Arm(_fails("move_to", lambda v: v == APPROACH_SPEED, "stopped", Outcome.COLLISION))
    res = _run(arm)
    assert res.outcome is Outcome.COLLISION and res.reason.startswith("approach: stopped")
    assert _parked(arm) and res.stream is None  # opened and retreated after the failure


def test_the_reason_text_no_longer_decides_the_outcome() -> None:
    """A motion that names no outcome is the step's, whatever its message says: the old
    substring rules would have made this one a collision."""
    reason = "target not reached; collision in scene: hand with board (no IK, joint limit)"
    arm = _Arm(_fails("move_to", lambda v: v == APPROACH_SPEED, reason, None))
    assert _run(arm).outcome is Outcome.GRASP_NOT_HELD
    arm = _Arm(_fails("move_to", lambda v: v == STROKE_SPEED, reason, None))
    res = _run(arm)
    assert res.outcome is Outcome.ACTION_FAILED and res.reason.startswith("action 0 (along)")
    arm = _Arm(_fails("move_to", lambda v: v == STROKE_SPEED, "refused", Outcome.UNREACHABLE))
    assert _run(arm).outcome is Outcome.UNREACHABLE


def test_nothing_held_is_grasp_not_held() -> None:
    res = _run(_Arm(held=False))
    assert res.outcome is Outcome.GRASP_NOT_HELD and res.reason.startswith("close: nothing held")


class _FirstGraspEmpty(_Arm):
    """The first close holds nothing; the back-out to its pre-grasp (the first motion at
    approach speed after it) stops ``short_by`` m off its target; every later grasp holds."""

    def __init__(self, short_by: float) -> None:
        super().__init__(self._script)
        self.short_by, self.grasps, self.backed_out = short_by, 0, False

    def grasp(self, width=0.015, force=70.0, speed=0.05, epsilon_inner=0.01, epsilon_outer=0.01):
        self.grasps += 1
        return self.grasps > 1

    def _script(self, kind: str, arg) -> MoveResult | None:
        if kind == "move_to" and arg == APPROACH_SPEED and self.grasps == 1 and not self.backed_out:
            self.backed_out = True
            why = "target not reached within tolerance (a hose brushed the open hand)"
            return MoveResult(False, why, self.short_by, outcome=Outcome.COLLISION)
        return None


@pytest.mark.parametrize("short_by", [0.0044, 0.03])
def test_a_back_out_that_stops_short_of_the_pregrasp_still_leads_to_the_retry(short_by) -> None:
    """The first grasp closes on nothing, and backing out to its pre-grasp stops short (the
    open hand brushes a hose; seed 6371 of the fast counts did this until the finger pads' stop
    of 823df36 made its first grasp hold).  Within ``hold_check_distance`` (1 cm) the hand is
    clear of the hose: the neighbouring point is tried, and it holds.  Farther off, the grasp
    ends as ``grasp_not_held`` with the back-out's reason and no retry."""
    cfg = GraspConfig(retries=2, approach_speed=APPROACH_SPEED)
    arm = _FirstGraspEmpty(short_by)
    centre, axis = np.array([0.5, 0.0, 0.3]), np.array([0.0, 1.0, 0.0])
    r = prim.grasp_at(arm, centre, axis, cfg, approach=(1.0, 0.0, 0.0))
    attempts = r.details["attempts"]
    assert attempts[0]["result"].startswith("close: nothing held")
    if short_by <= cfg.hold_check_distance:
        assert r, r.reason
        assert r.details["retries"] == 1 and len(attempts) == 2
        assert attempts[0]["back_out_short_by_m"] == short_by
        assert attempts[1]["result"] == "held"
        assert abs(attempts[1]["offset_m"]) == pytest.approx(cfg.retry_shift)
    else:
        assert not r and r.outcome is Outcome.GRASP_NOT_HELD and arm.grasps == 1
        assert len(attempts) == 1 and "target not reached" in attempts[0]["back_out"]


def test_a_failed_retreat_is_retreat_failed_whatever_the_motion_says() -> None:
    arm = _Arm(
        _fails("move_joints", lambda q: q == tuple(np.round(PARK, 6)), "hit", Outcome.COLLISION)
    )
    res = _run(arm)
    assert res.outcome is Outcome.RETREAT_FAILED and len(res.actions) == 2


def test_an_invalid_segment_moves_nothing() -> None:
    arm = _Arm()
    res = _run(arm, segment=np.zeros((H, W), bool))
    assert res.outcome is Outcome.SEGMENT_INVALID and res.reason.startswith("segment:")
    assert arm.log == []


def test_a_push_out_of_reach_fails_before_moving_and_leaves_nothing_to_clean() -> None:
    class _Far(_Arm):
        def check_reachable(self, pose: Pose) -> tuple[bool, str]:
            return False, "IK did not converge"

    arm = _Far()
    res = _run(arm, kind="push")
    assert res.outcome is Outcome.UNREACHABLE and res.reason.startswith("push: unreachable")
    assert not any(k.startswith("move") for k, _ in arm.log)  # no release and retreat


def test_the_phases_share_one_state_and_stop_at_the_first_failure() -> None:
    cam, arm = _Board(), _Arm(held=False)
    state = InteractionState.begin(arm, cam, PlanningClock(cam), _segment(), _config())
    ran = []
    for phase in PHASES:
        ran.append(phase.__name__)
        if not phase(state):
            break
    assert ran == ["locate", "grasp"]
    assert state.result.outcome is Outcome.GRASP_NOT_HELD and state.result.centre is not None
    assert [p.__name__ for p in PHASES] == ["locate", "grasp", "act", "retreat", "finish"]


# ---------------------------------------------------------------------- the primitives
@pytest.mark.parametrize(
    ("named", "expected"),
    [(None, Outcome.ACTION_FAILED), (Outcome.COLLISION, Outcome.COLLISION)],
)
def test_a_failed_stroke_is_action_failed_unless_the_motion_named_it(named, expected) -> None:
    arm = _Arm(_fails("move_to", lambda v: True, "stopped", named))
    r = prim.periodic_action(arm, Pose(np.zeros(3)), np.array([0.0, 1.0, 0.0]), 0.02, 1)
    assert not r and r.outcome is expected and "stroke 1/4" in r.reason


def test_release_and_retreat_name_their_failures() -> None:
    class _Stuck(_Arm):
        def open(self, width: float = 0.08, speed: float = 0.1) -> bool:
            return False

    assert prim.release(_Stuck()).outcome is Outcome.RELEASE_FAILED
    assert prim.release(_Arm()).outcome is Outcome.OK
    arm = _Arm(_fails("move_joints", lambda q: True, "collision in scene: x", Outcome.COLLISION))
    assert prim.retreat(arm, PARK).outcome is Outcome.RETREAT_FAILED


def test_a_gripper_that_does_not_open_for_a_retry_is_release_failed_and_ends_the_grasp() -> None:
    class _Jams(_Arm):
        """Holds nothing, and its fingers stay shut once they have closed."""

        closed = False

        @property
        def gripper_opening(self) -> float:
            return -0.0139 if self.closed else 0.08

        def open(self, width: float = 0.08, speed: float = 0.1) -> bool:
            self.log.append(("open", width))
            return not self.closed

        def grasp(
            self, width=0.015, force=70.0, speed=0.05, epsilon_inner=0.01, epsilon_outer=0.01
        ):
            self.closed = True
            return False

    arm = _Jams()
    cfg = dataclasses.replace(_config().grasp, retries=2)
    r = prim.grasp_at(arm, np.array([1.0, 0.0, 1.0]), np.array([0.0, 1.0, 0.0]), cfg)
    assert r.outcome is Outcome.RELEASE_FAILED
    assert r.reason == "grasp: the gripper did not open (opening -13.9 mm)"
    # the first attempt closed on nothing; the second found the gripper shut and stopped there
    first, second = (a["result"] for a in r.details["attempts"])
    assert first.startswith("close: nothing held") and second == r.reason
    assert r.moved


def test_a_move_to_the_pre_grasp_out_of_reach_is_unreachable() -> None:
    arm = _Arm(_fails("move_joints", lambda q: True, "could not", None))
    cfg = dataclasses.replace(_config().grasp, standoff=0.0)
    r = prim.grasp_at(arm, np.array([1.0, 0.0, 1.0]), np.array([0.0, 1.0, 0.0]), cfg)
    assert r.outcome is Outcome.UNREACHABLE and r.reason.startswith("move to pre-grasp")
    assert r.moved and r.details["moved"]
