"""The arm model's IK memo: the same problem gets the same answer without iterating, bit for
bit what a fresh solve gives, and a problem that differs in any input is solved anew."""

from __future__ import annotations

import numpy as np

from cablesim.panda import HOME_QPOS, ik
from cablesim.panda.ik import ArmModel


def _problems(arm: ArmModel, n: int = 6) -> list:
    """Reachable and unreachable targets around the home pose, with their starts."""
    rng = np.random.default_rng(4)
    home = arm.fk(np.asarray(HOME_QPOS, float))
    out = []
    for k in range(n):
        reach = 0.05 if k % 2 == 0 else 1.2  # every other target is out of reach
        target = home.translated(rng.normal(size=3) * reach)
        q0 = np.asarray(HOME_QPOS, float) + rng.normal(size=7) * 0.05
        out.append((target, q0))
    return out


def test_a_repeated_problem_is_answered_from_the_memo_as_a_fresh_solve_would() -> None:
    arm, fresh = ArmModel(), ArmModel()
    problems = _problems(arm)
    first = [arm.solve(t, q0, q0, 0.08) for t, q0 in problems]
    assert arm.solve_hits == 0 and arm.solve_calls == len(problems)
    assert any(r.converged for r in first) and not all(r.converged for r in first)
    again = [arm.solve(t, q0, q0, 0.08) for t, q0 in problems]
    assert arm.solve_hits == len(problems)
    for a, b, (t, q0) in zip(first, again, problems, strict=True):
        c = fresh.solve(t, q0, q0, 0.08)  # another model, never asked before
        for r in (b, c):
            assert r.converged == a.converged and r.iterations == a.iterations
            assert r.position_error == a.position_error
            assert r.rotation_error == a.rotation_error
            np.testing.assert_array_equal(r.q, a.q)
    # a caller changing the answer it got does not change the memo
    again[0].q[:] = 0.0
    np.testing.assert_array_equal(arm.solve(*problems[0], problems[0][1], 0.08).q, first[0].q)


def test_any_change_of_the_problem_is_solved_anew() -> None:
    arm = ArmModel()
    (target, q0), *_ = _problems(arm)
    arm.solve(target, q0, q0, 0.08)
    variants = [
        (target.translated([1e-9, 0.0, 0.0]), q0, q0, 0.08),
        (target, q0 + 1e-9, q0, 0.08),
        (target, q0, None, 0.08),
        (target, q0, q0 + 1e-9, 0.08),
        (target, q0, q0, 0.06),
    ]
    for v in variants:
        arm.solve(*v)
    assert arm.solve_hits == 0
    arm.max_iterations = 30  # the tolerances and iteration budget are part of the problem
    arm.solve(target, q0, q0, 0.08)
    assert arm.solve_hits == 0


def test_the_memo_is_bounded(monkeypatch) -> None:
    monkeypatch.setattr(ik, "IK_MEMO_SIZE", 3)
    arm = ArmModel()
    problems = _problems(arm, 5)
    for t, q0 in problems:
        arm.solve(t, q0, q0, 0.08)
    assert len(arm._solved) == 3  # noqa: SLF001
    arm.solve(*problems[0], problems[0][1], 0.08)  # the oldest was dropped
    assert arm.solve_hits == 0
    arm.solve(*problems[-1], problems[-1][1], 0.08)
    assert arm.solve_hits == 1
