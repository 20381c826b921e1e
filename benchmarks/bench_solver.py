"""Where the physics time of one default interaction goes: steps, solver and iterations per
phase, and what MuJoCo's constraint solver does in the states where Newton stalls.

    .venv/bin/python -m benchmarks.bench_solver [--seed 2] [--timestep 0.004]
        [--replay SEED:T ...] [--write]

Part 1 runs one default interaction (no perception) and counts, per phase (approach and grasp,
each action, release, retreat), the physics steps, which solver ran them (Newton, or CG
standing in after a Newton step that hit its iteration limit: ``cablesim.sim.world``), the
mean solver iterations and the CPU time per step.  Part 2 saves the states in which Newton
stalled during the actions and re-solves each of them once per solver option: iterations
until convergence (100 = the limit, not converged) and CPU ms per step.  ``--timestep``
compares another physics timestep (its scene is settled anew, so it is a different scene
state; the follow gains are reported).  ``--replay SEED:T`` (part 3) saves the state of seed
SEED's default interaction at T s, a little before a blow-up, and steps on from it with each
solver setting of ``REPLAY_SOLVERS``: the largest hose stretch says which setting tears the
hose.  ``--write`` writes ``benchmarks/results/solver.md``.
The machine is shared: iteration counts are exact, times are indicative.
"""

from __future__ import annotations

import benchmarks._env  # noqa: F401  (one thread, headless GL: before numpy and MuJoCo)

# isort: split
import argparse
import sys
import time

import numpy as np

import cablesim  # noqa: F401  (selects the headless GL back end; mujoco after it)
from benchmarks import RESULTS, write_results
from benchmarks._interaction import (
    run_meta,
    single_thread_environment,
    uptime,
)

OUT = RESULTS / "solver.md"
PHASES = ("grasp_at", "periodic_action", "release", "retreat")
SOLVER_NAMES = {0: "PGS", 1: "CG", 2: "Newton"}
#: solver options tried on the stalled states: name -> {mjOption field: value}
OPTIONS: dict[str, dict[str, float]] = {
    "Newton, sparse (default)": {},
    "Newton, tolerance 1e-6": {"tolerance": 1e-6},
    "Newton, 100 line-search iterations": {"ls_iterations": 100},
    "Newton, dense Jacobian": {"jacobian": 0},
    "Newton, pyramidal cone": {"cone": 0},
    "Newton, 300 iterations": {"iterations": 300},
    "CG (the fallback)": {"solver": 1},
}


def run(seed: int, timestep: float) -> dict:
    import mujoco

    import cablesim.episode.primitives as prim
    import cablesim.sim.world as world_mod
    from cablesim.config import override
    from cablesim.sim.config import EpisodeConfig
    from cablesim.sim.session import SimSession

    cfg = override(EpisodeConfig.of(seed=seed), f"scene.physics.timestep={timestep}")
    session = SimSession.build(cfg)
    segment = session.pick_start()
    hose = session.hose
    session = SimSession.build(cfg, world=session.world, camera=session.camera)
    session.hose = hose
    w = session.world
    m, d = w.model, w.data
    state_spec = mujoco.mjtState.mjSTATE_FULLPHYSICS | mujoco.mjtState.mjSTATE_CTRL
    phase = ["other"]
    steps: dict[tuple[str, int], list[float]] = {}
    stalled: list[np.ndarray] = []
    step_fn = mujoco.mj_step

    def counted_step(m_, d_, *a):
        solver = int(m_.opt.solver)
        c = time.process_time()
        step_fn(m_, d_, *a)
        c = time.process_time() - c
        s = steps.setdefault((phase[0], solver), [0, 0.0, 0])
        s[0] += 1
        s[1] += c
        s[2] += w.solver_iterations()

    advance = w._advance  # noqa: SLF001

    def watched_advance():
        if phase[0] == "periodic_action" and w._fallback_steps == 0 and len(stalled) < 40:  # noqa: SLF001
            st = np.empty(mujoco.mj_stateSize(m, state_spec))
            mujoco.mj_getState(m, d, st, state_spec)
            before = w.solver_fallbacks
            advance()
            if w.solver_fallbacks > before:
                stalled.append(st)
            return
        advance()

    originals = {n: getattr(prim, n) for n in PHASES}

    def in_phase(name):
        def wrapped(*a, **k):
            phase[0] = name
            try:
                return originals[name](*a, **k)
            finally:
                phase[0] = "other"

        return wrapped

    world_mod.mujoco.mj_step = counted_step
    w._advance = watched_advance  # noqa: SLF001
    for n in PHASES:
        setattr(prim, n, in_phase(n))
    try:
        c0 = time.process_time()
        res = session.interact(segment.mask)
        cpu = time.process_time() - c0
    finally:
        world_mod.mujoco.mj_step = step_fn
        w._advance = advance  # noqa: SLF001
        for n, f in originals.items():
            setattr(prim, n, f)
    trials = []
    if stalled:
        base = {
            k: getattr(m.opt, k)
            for k in ("tolerance", "ls_iterations", "jacobian", "cone", "iterations", "solver")
        }
        for name, opts in OPTIONS.items():
            for k, v in {"solver": 2, **opts}.items():
                setattr(m.opt, k, type(getattr(m.opt, k))(v))
            its = []
            c = time.process_time()
            for st in stalled:
                mujoco.mj_setState(m, d, st, state_spec)
                mujoco.mj_step(m, d)
                its.append(w.solver_iterations())
            ms = 1e3 * (time.process_time() - c) / len(stalled)
            limit = int(m.opt.iterations)
            for k, v in base.items():
                setattr(m.opt, k, v)
            trials.append(
                {
                    "option": name,
                    "median_iterations": float(np.median(its)),
                    "not_converged": sum(i >= limit for i in its),
                    "ms_per_step": ms,
                }
            )
    session.close()
    return {
        "seed": seed,
        "timestep": timestep,
        "success": bool(res.success),
        "cpu_s": cpu,
        "gains": [a.gain for a in res.actions],
        "fallbacks": w.solver_fallbacks,
        "steps": {f"{p}/{SOLVER_NAMES.get(s, s)}": v for (p, s), v in sorted(steps.items())},
        "stalled": len(stalled),
        "trials": trials,
    }


#: solver settings a replay compares: name -> (solver: 1 CG / 2 Newton, iterations, dense)
REPLAY_SOLVERS: dict[str, tuple[int, int, bool]] = {
    "CG, 100 iterations (the fallback)": (1, 100, False),
    "CG, 1000 iterations": (1, 1000, False),
    "Newton, sparse (the default)": (2, 100, False),
    "Newton, dense Jacobian": (2, 100, True),
}


def replay(seed: int, t_save: float, duration: float) -> dict:
    """Run the default interaction of ``seed`` (stretch check off) up to ``t_save`` s of
    simulated time, save the state, and step ``duration`` s from it once per solver setting
    of :data:`REPLAY_SOLVERS`: the largest hose edge stretch and the solver's iterations."""
    import mujoco

    from cablesim.config import override
    from cablesim.sim.config import EpisodeConfig
    from cablesim.sim.session import SimSession

    cfg = override(EpisodeConfig.of(seed=seed), "scene.physics.max_hose_strain=10.0")
    session = SimSession.build(cfg)
    segment = session.pick_start()
    w = session.world
    m, d = w.model, w.data
    spec = (
        mujoco.mjtState.mjSTATE_FULLPHYSICS
        | mujoco.mjtState.mjSTATE_CTRL
        | mujoco.mjtState.mjSTATE_EQ_ACTIVE
    )
    saved: dict = {}

    class _Saved(Exception):
        pass

    advance = w._advance  # noqa: SLF001

    def watched() -> None:
        advance()
        if d.time >= t_save:
            saved["state"] = np.empty(mujoco.mj_stateSize(m, spec))
            mujoco.mj_getState(m, d, saved["state"], spec)
            saved["solver"] = SOLVER_NAMES.get(int(m.opt.solver), m.opt.solver)
            raise _Saved

    w._advance = watched  # noqa: SLF001
    try:
        session.interact(segment.mask)
    except _Saved:
        pass
    finally:
        w._advance = advance  # noqa: SLF001
    rows = []
    if saved:
        base = (m.opt.solver, m.opt.iterations, m.opt.jacobian)
        for name, (solver, iterations, dense) in REPLAY_SOLVERS.items():
            mujoco.mj_setState(m, d, saved["state"], spec)
            m.opt.solver, m.opt.iterations = solver, iterations
            if dense:
                m.opt.jacobian = 0
            stretch, its = 0.0, []
            for _ in range(round(duration / m.opt.timestep)):
                mujoco.mj_step(m, d)
                its.append(w.solver_iterations())
                stretch = max(stretch, float(w.hose_stretch().max()))
            m.opt.solver, m.opt.iterations, m.opt.jacobian = base
            rows.append(
                {
                    "solver": name,
                    "max_stretch": stretch,
                    "median_iterations": float(np.median(its)),
                    "at_limit": float(np.mean(np.asarray(its) >= iterations)),
                }
            )
    session.close()
    return {
        "seed": seed,
        "t": float(t_save),
        "duration": duration,
        "running": saved.get("solver"),
        "rows": rows,
    }


def report_replays(replays: list[dict]) -> list[str]:
    lines = [
        "## Blow-ups replayed",
        "",
        "Seeds whose default interaction tore a hose (`benchmarks/results/seeds.md`, outcome "
        "`diverged`): the state a little before the runaway is saved and stepped on with each "
        "solver setting (`--replay SEED:T`).  A hose edge stretches by ~1 % at rest and up to "
        "~16 % when an action pulls a taut hose; 50 % is the divergence limit.",
        "",
        "| seed, from t (s), solver running there | solver setting | max stretch | median "
        "iterations | steps at the iteration limit |",
        "|---|---|---|---|---|",
    ]
    for r in replays:
        for row in r["rows"]:
            lines.append(
                f"| {r['seed']}, {r['t']:.2f} + {r['duration']:.1f} s, {r['running']} | "
                f"{row['solver']} | {row['max_stretch']:.0%} | {row['median_iterations']:.0f} | "
                f"{row['at_limit']:.0%} |"
            )
    lines.append("")
    return lines


def report(runs: list[dict], meta: dict) -> str:
    lines = [
        "# Solver benchmark: where the physics time of one interaction goes",
        "",
        "`python -m benchmarks.bench_solver --write`: one default interaction (no perception), "
        "physics "
        "steps per phase and solver, then the states where Newton stalled during the actions "
        "re-solved with other solver options.",
        "",
        f"- date: {meta['date']}; cablesim commit {meta['commit']}",
        f"- machine: {meta['machine']}; {meta['versions']}",
        f"- load (shared machine), start `{meta['load_start']}`, end `{meta['load_end']}`: "
        "times are indicative, iteration counts exact",
        "",
    ]
    for r in runs:
        lines += [
            f"## Seed {r['seed']}, timestep {r['timestep'] * 1000:g} ms",
            "",
            f"Interaction {'ok' if r['success'] else 'FAILED'}, {r['cpu_s']:.1f} s CPU "
            f"(physics, control, rendering, ground truth); follow gain "
            f"{', '.join(f'{g:.3f}' for g in r['gains'])}; {r['fallbacks']} Newton steps redone "
            "with CG (each starts 1 s of CG).",
            "",
            "| phase / solver | steps | mean iterations | CPU ms per step | CPU s |",
            "|---|---|---|---|---|",
        ]
        for k, (n, c, it) in r["steps"].items():
            lines.append(f"| {k} | {n} | {it / n:.1f} | {1e3 * c / n:.2f} | {c:.2f} |")
        if r["trials"]:
            lines += [
                "",
                f"{r['stalled']} states in which Newton stalled during the actions, each "
                "re-solved once per option (limit 100 iterations unless stated):",
                "",
                "| option | median iterations | not converged | CPU ms per step |",
                "|---|---|---|---|",
            ]
            for t in r["trials"]:
                lines.append(
                    f"| {t['option']} | {t['median_iterations']:.0f} | "
                    f"{t['not_converged']}/{r['stalled']} | {t['ms_per_step']:.2f} |"
                )
        lines.append("")
    return "\n".join(lines)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seed", type=int, default=2)
    ap.add_argument("--timestep", type=float, action="append", help="default: 0.004")
    ap.add_argument(
        "--replay",
        action="append",
        default=[],
        metavar="SEED:T",
        help="replay the default interaction of SEED from T s with each solver setting",
    )
    ap.add_argument("--replay-duration", type=float, default=0.3)
    ap.add_argument("--write", action="store_true")
    args = ap.parse_args()
    single_thread_environment()  # before the first rendering (and the workers)
    load_start = uptime()
    runs = [run(args.seed, dt) for dt in (args.timestep or [0.004])]
    replays = []
    for spec in args.replay:
        seed, _, t = spec.partition(":")
        replays.append(replay(int(seed), float(t), args.replay_duration))
    meta = run_meta(load_start=load_start, load_end=uptime())
    text = report(runs, meta)
    if replays:
        text += "\n" + "\n".join(report_replays(replays))
    print(text)
    if args.write:
        write_results(OUT, text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
