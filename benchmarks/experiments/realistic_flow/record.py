"""Recording half of ``python -m benchmarks.experiments.realistic_flow``: one grasp
interaction per scene, recorded once into a cache outside the repository and reused by every
perception variant.

Each scene: ``EpisodeConfig.of(seed=s, perturb=PerturbConfig(enabled=True))`` with kinematic arm
masks captured (``capture.arm_masks``), ground truth on, the camera noise-free (the noise
models of :mod:`cablesim.sim.sensor` are applied to the recorded clean images when perception
runs, so every noisy result has its noise-free twin on the very same interaction).  A scene
whose interaction fails leaves ``<dir>.failed.json`` with the reason; a scene already recorded
(or failed) is skipped, so the recording resumes where it stopped.  A recording made before
the runner's slip rule whose hose slipped during an action (:func:`slipped`) counts as failed.
"""

from __future__ import annotations

import json
import os
import shutil
import time
import traceback
from collections.abc import Iterable
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from dataclasses import dataclass
from pathlib import Path

from cablesim.cables import DEFAULT_KIND

CACHE = Path(os.environ.get("CABLESIM_STREAMS", Path.home() / ".cache" / "cablesim" / "streams"))
#: bump when the recorded interaction changes (a new tag records into a new folder); rf2: the
#: perturbation's damping capped for stability (cablesim.sim.perturb.stable_damping)
TAG = "rf2"


#: recorded settings: "default" (640x480, 3 periods per action), "thesis" (the D456 at
#: 1280x720) and "fast" (320x240 and 2 periods per action: the setting that brings one
#: interaction near issue 9's 12 s here, benchmarks/results/episode_variants.md) and "sleep"
#: (the default with MuJoCo's sleeping islands on, ``physics.sleep_tolerance`` 1e-3: issue 21's
#: lever, scored against the default on the same protocol) and "before21" (the default's
#: physics before issue 21's two physics changes: every hose awake while the arm is in transit,
#: ``physics.transit_sleep`` 0, and CG standing in for 1 s after each Newton stall in every
#: step, ``physics.run_fallback_time`` None; the recordings named "default" before them were
#: renamed "before21", since they are these)
GEOMETRIES = ("default", "thesis", "fast", "sleep", "before21")
#: ``physics.sleep_tolerance`` of the "sleep" setting (benchmarks/results/sleep_islands.md)
SLEEP_TOLERANCE = 1e-3
#: what the cables are and what holds them (issue 22): a scene of the default hose on the board
#: keeps its old name (and its recordings); any other kind or surface is named after them
DEFAULT_CABLE, DEFAULT_SURFACE = DEFAULT_KIND, "board"


@dataclass(frozen=True)
class Scene:
    split: str  # "val" | "test"
    seed: int
    board: str  # "wood" | "solid"
    geometry: str = "default"  # a key of GEOMETRIES
    cable: str = DEFAULT_CABLE  # a kind of cablesim.cables.CABLE_KINDS, for every cable
    surface: str = DEFAULT_SURFACE  # "board" | "table"; on the table ``board`` is the mat's look

    @property
    def name(self) -> str:
        return f"{self.split}-{self.seed}-{self.board}-{self.geometry}{suffix(self.cable, self.surface)}"

    @property
    def path(self) -> Path:
        return CACHE / TAG / self.name

    @property
    def stats_path(self) -> Path:
        """Where ``evaluate`` caches this scene's perception statistics."""
        return CACHE / TAG / "stats" / self.name

    @property
    def failed_path(self) -> Path:
        return self.path.with_name(self.path.name + ".failed.json")

    def status(self) -> str:
        """'ok' (complete recording), 'failed' or 'todo'."""
        if self.failed_path.exists():
            return "failed"
        meta = self.path / "meta.json"
        if meta.exists():
            try:
                doc = json.loads(meta.read_text())
            except (OSError, ValueError):
                return "todo"
            if doc.get("complete"):
                return "failed" if slipped(doc) else "ok"
        return "todo"

    def config(self):
        from cablesim.episode.config import ActionConfig, CaptureConfig, InteractionConfig
        from cablesim.sim.config import (
            CameraConfig,
            EpisodeConfig,
            PerturbConfig,
            SceneConfig,
        )

        if self.geometry not in GEOMETRIES:
            raise ValueError(f"geometry {self.geometry!r}: not one of {GEOMETRIES}")
        camera, actions = CameraConfig(), ActionConfig()
        if self.geometry == "thesis":
            camera = CameraConfig.thesis()
        elif self.geometry == "fast":
            camera = CameraConfig(width=320, height=240)
            actions = ActionConfig(periods=2)
        # the wood / solid look: the board's, and on the table the mat's too
        looks = {"board.background": self.board}
        if self.surface == "table":
            looks["table.background"] = self.board
        if self.geometry == "sleep":
            looks["physics.sleep_tolerance"] = SLEEP_TOLERANCE
        elif self.geometry == "before21":
            looks["physics.transit_sleep"] = 0.0
            looks["physics.run_fallback_time"] = None
        scene = SceneConfig(seed=self.seed, camera=camera).with_values(
            {"surface": self.surface, "hoses.kind": self.cable, **looks}
        )
        return EpisodeConfig(
            scene=scene,
            # every frame labelled: the oracle rows read each frame's ground-truth flow
            interaction=InteractionConfig(
                actions=actions, capture=CaptureConfig(arm_masks=True, truth_every=1)
            ),
            perturb=PerturbConfig(enabled=True),
        )


def suffix(cable: str = DEFAULT_CABLE, surface: str = DEFAULT_SURFACE) -> str:
    """What a scene's name ends with for ``cable`` on ``surface`` ("" for the default hose on
    the board)."""
    if (cable, surface) == (DEFAULT_CABLE, DEFAULT_SURFACE):
        return ""
    return f"-{surface}-{cable}"


def slipped(doc: dict) -> bool:
    """Whether a recording made before the runner's slip rule (``grasp.min_follow_r2``, now
    ``grasp_not_held``) shows a hose that slipped in the gripper during an action."""
    from cablesim.episode.config import GraspConfig

    r2_min = GraspConfig().min_follow_r2
    actions = doc.get("meta", {}).get("result", {}).get("actions", [])
    return any(
        a.get("gain_r2") is not None and a["gain_r2"] == a["gain_r2"] and a["gain_r2"] < r2_min
        for a in actions
    )


def record_scene(scene: Scene) -> tuple[Scene, str, float]:
    """Simulate and record one scene (in a worker process); (scene, status, seconds)."""
    import cablesim  # noqa: F401  (headless GL before mujoco)
    from cablesim.sim.session import simulate_episode

    t0 = time.process_time()
    if scene.status() != "todo":
        return scene, scene.status(), 0.0
    scene.path.parent.mkdir(parents=True, exist_ok=True)
    # perception statistics cached from an earlier recording of this name describe other frames
    # (evaluate reused them after a scene was recorded again, giving stale scores)
    shutil.rmtree(scene.stats_path, ignore_errors=True)
    try:
        ep = simulate_episode(scene.config(), record_to=scene.path, overwrite=True)
        ok, reason = ep.result.success, ep.result.reason
        ep.close()
    except Exception as e:  # noqa: BLE001 - a failed scene is recorded as failed
        ok, reason = False, f"{type(e).__name__}: {e}\n{traceback.format_exc(limit=3)}"
    if not ok:
        scene.failed_path.write_text(json.dumps({"scene": scene.name, "reason": reason}))
    return scene, scene.status(), time.process_time() - t0


def _record_split(
    pool, split: str, seeds: Iterable[int], want: int, geometry: str, log, cable: str, surface: str
) -> list:
    """Wood-board scenes of ``split`` from ``seeds`` (in order) until ``want`` succeeded."""
    ok: list[Scene] = []
    pending: dict[Future, Scene] = {}
    it = iter(seeds)

    def submit_next() -> bool:
        for seed in it:
            sc = Scene(split, seed, "wood", geometry, cable, surface)
            st = sc.status()
            if st == "ok":
                ok.append(sc)
                if len(ok) >= want:
                    return False
                continue
            if st == "failed":
                continue
            pending[pool.submit(record_scene, sc)] = sc
            return True
        return False

    while len(ok) + len(pending) < want and submit_next():
        pass
    while pending:
        done, _ = wait(pending, return_when=FIRST_COMPLETED)
        for fut in done:
            sc = pending.pop(fut)
            _, st, secs = fut.result()
            log(f"  {sc.name}: {st} ({secs:.0f} s CPU)")
            if st == "ok":
                ok.append(sc)
        while len(ok) + len(pending) < want and submit_next():
            pass
    ok.sort(key=lambda s: s.seed)
    return ok[:want]


def record(
    splits: dict[str, tuple[Iterable[int], int]],
    solid: dict[str, int],
    workers: int = 2,
    geometry: str = "default",
    log=print,
    cable: str = DEFAULT_CABLE,
    surface: str = DEFAULT_SURFACE,
) -> dict[str, list[Scene]]:
    """Record, per split, scenes from its seed range until ``want`` succeeded on the wood board;
    then the first ``solid[split]`` of those again on the solid board.  Returns the recorded
    (ok) scenes per split and board, in seed order."""
    out: dict[str, list[Scene]] = {}
    with ProcessPoolExecutor(max_workers=workers) as pool:
        for split, (seeds, want) in splits.items():
            ok = _record_split(pool, split, seeds, want, geometry, log, cable, surface)
            out[f"{split}/wood"] = ok
            sol = [
                Scene(split, s.seed, "solid", geometry, cable, surface)
                for s in ok[: solid.get(split, 0)]
            ]
            futs = {pool.submit(record_scene, s): s for s in sol if s.status() == "todo"}
            for fut in futs:
                _, st, secs = fut.result()
                log(f"  {futs[fut].name}: {st} ({secs:.0f} s CPU)")
            out[f"{split}/solid"] = [s for s in sol if s.status() == "ok"]
    return out


def recorded(
    split: str,
    board: str,
    geometry: str = "default",
    cable: str = DEFAULT_CABLE,
    surface: str = DEFAULT_SURFACE,
) -> list[Scene]:
    """The scenes of ``split`` recorded so far (ok), in seed order."""
    root = CACHE / TAG
    out = []
    for p in sorted(root.glob(f"{split}-*-{board}-{geometry}{suffix(cable, surface)}")):
        if p.is_dir():
            sc = Scene(split, int(p.name.split("-")[1]), board, geometry, cable, surface)
            if sc.status() == "ok":
                out.append(sc)
    return sorted(out, key=lambda s: s.seed)
