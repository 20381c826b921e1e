"""Train Stable-Baselines3 PPO on ``cablesim/HoseExploreBox-v0`` (fast configuration, aimed
residual actions) and compare it with a random policy on held-out seeds.

    pip install -e '.[rl]'          # stable-baselines3 (and the CPU torch it runs on)
    python -m cablesim.envs.train_ppo --steps 256 --n-steps 32 --out runs/ppo

(``tests/envs/test_box.py`` runs it with ``--steps 32 --n-steps 16``.)

Every environment step is a full simulated interaction (about 1.5-2 s of CPU in the fast
configuration when the hand reaches the hose, well under 0.1 s when the action is refused as
unreachable), so a few hundred steps take minutes.  What it does:

1. builds the environment (:func:`cablesim.envs.box.make_box_env` with
   :func:`~cablesim.envs.box.fast_config`, ``aimed=True``) and ``PPO("MultiInputPolicy")``
   (a CNN on ``obs["image"]``, an MLP on ``obs["gripper"]``), seeded;
2. records the untrained policy's deterministic primitive switch ``a[0]`` (< 0: grasp) on the
   first observation of each evaluation seed;
3. learns for ``steps`` environment steps;
4. evaluates, on the same evaluation seeds (disjoint from the training episodes' seeds), the
   trained policy (deterministic) and a uniformly random policy (seeded), one episode each;
   prints (and with ``--out`` writes ``ppo.json``) the returns, the switch values, the share of
   grasps and the CPU time.

In the fast configuration a push earns nothing (it moves the hose too little for a mask) and an
aimed grasp earns a gain in F0.4 of about 0.4-0.9, so what PPO learns first is to grasp.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import resource
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from cablesim.errors import CablesimError, ConfigError

from .box import fast_config, make_box_env


@dataclass
class PPORun:
    """What :func:`train_and_evaluate` measured."""

    steps: int
    eval_seeds: list[int]
    switch_before: list[float]  # deterministic a[0] of the untrained policy per eval seed
    switch_after: list[float]  # the same after learning (< 0: grasp)
    trained_returns: list[float]
    random_returns: list[float]
    train_cpu_s: float
    train_wall_s: float
    eval_cpu_s: float
    train_episode_returns: list[float] = field(default_factory=list)
    config: dict[str, Any] = field(default_factory=dict)

    @property
    def trained_mean(self) -> float:
        return float(np.mean(self.trained_returns))

    @property
    def random_mean(self) -> float:
        return float(np.mean(self.random_returns))

    def summary(self) -> str:
        grasps = sum(s < 0 for s in self.switch_after)
        return (
            f"PPO {self.steps} steps in {self.train_cpu_s:.0f} s CPU "
            f"({self.train_wall_s:.0f} s wall); eval seeds {self.eval_seeds}: "
            f"trained (deterministic) mean return {self.trained_mean:.3f}, "
            f"random {self.random_mean:.3f}; switch a[0] mean "
            f"{np.mean(self.switch_before):+.3f} before -> {np.mean(self.switch_after):+.3f} "
            f"after ({grasps}/{len(self.switch_after)} grasps)"
        )

    def to_dict(self) -> dict[str, Any]:
        d = dataclasses.asdict(self)
        d.update(trained_mean=self.trained_mean, random_mean=self.random_mean)
        return d


def _cpu() -> float:
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


def _episode(env: Any, seed: int, act: Any) -> float:
    obs, _ = env.reset(seed=seed)
    total, done = 0.0, False
    while not done:
        obs, reward, terminated, truncated, _ = env.step(act(obs))
        total += float(reward)
        done = terminated or truncated
    return total


def train_and_evaluate(
    steps: int = 256,
    n_steps: int = 32,
    batch_size: int | None = None,
    n_epochs: int = 10,
    learning_rate: float = 1e-3,
    seed: int = 0,
    eval_seeds: tuple[int, ...] = (1000, 1001, 1002, 1003),
    budget: int = 1,
    scene_seed: int = 2,
    env_kwargs: dict[str, Any] | None = None,
) -> PPORun:
    """Train PPO for ``steps`` environment steps and evaluate it (module docstring)."""
    try:
        from stable_baselines3 import PPO  # lazy: optional heavy package
    except ImportError as e:  # the rl extra
        raise CablesimError("stable-baselines3 is not installed: pip install -e '.[rl]'") from e
    for name, value in (("steps", steps), ("n_steps", n_steps), ("n_epochs", n_epochs)):
        if isinstance(value, bool) or not isinstance(value, int) or value < 1:
            raise ConfigError(name, f"must be an integer >= 1, got {value!r}")
    if n_steps < 2:
        raise ConfigError("n_steps", f"PPO needs at least 2 steps per rollout, got {n_steps}")
    if not eval_seeds:
        raise ConfigError("eval_seeds", "need at least one evaluation seed")
    cfg = fast_config(budget=budget, scene_seed=scene_seed)
    kwargs = {"aimed": True, **(env_kwargs or {})}
    env = make_box_env(cfg, **kwargs)
    eval_env = make_box_env(cfg, **kwargs)
    try:
        model = PPO(
            "MultiInputPolicy",
            env,
            n_steps=n_steps,
            batch_size=batch_size or n_steps,
            n_epochs=n_epochs,
            learning_rate=learning_rate,
            seed=seed,
            stats_window_size=max(100, steps),  # keep every training episode's return
            device="cpu",
            verbose=0,
        )

        def switch(seeds: tuple[int, ...]) -> list[float]:
            out = []
            for s in seeds:
                obs, _ = eval_env.reset(seed=s)
                a, _ = model.predict(obs, deterministic=True)
                out.append(float(a[0]))
            return out

        before = switch(eval_seeds)
        cpu0, wall0 = _cpu(), time.perf_counter()
        model.learn(total_timesteps=steps)
        train_cpu, train_wall = _cpu() - cpu0, time.perf_counter() - wall0
        train_returns = [float(ep["r"]) for ep in model.ep_info_buffer]
        after = switch(eval_seeds)
        cpu0 = _cpu()
        trained = [
            _episode(eval_env, s, lambda o: model.predict(o, deterministic=True)[0])
            for s in eval_seeds
        ]
        rng = np.random.default_rng(seed)
        random = [
            _episode(eval_env, s, lambda o: rng.uniform(-1.0, 1.0, 4).astype(np.float32))
            for s in eval_seeds
        ]
        eval_cpu = _cpu() - cpu0
    finally:
        env.close()
        eval_env.close()
    return PPORun(
        steps=int(model.num_timesteps),
        eval_seeds=list(eval_seeds),
        switch_before=before,
        switch_after=after,
        trained_returns=trained,
        random_returns=random,
        train_cpu_s=train_cpu,
        train_wall_s=train_wall,
        eval_cpu_s=eval_cpu,
        train_episode_returns=train_returns,
        config={
            "n_steps": n_steps,
            "batch_size": batch_size or n_steps,
            "n_epochs": n_epochs,
            "learning_rate": learning_rate,
            "seed": seed,
            "budget": budget,
            "scene_seed": scene_seed,
            "env": {k: v for k, v in kwargs.items()},
        },
    )


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", type=int, default=256, help="environment steps to learn for")
    ap.add_argument("--n-steps", type=int, default=32, help="PPO rollout length")
    ap.add_argument("--epochs", type=int, default=10)
    ap.add_argument("--lr", type=float, default=1e-3)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--budget", type=int, default=1, help="interactions per episode")
    ap.add_argument("--eval-seeds", default="1000,1001,1002,1003")
    ap.add_argument("--out", type=Path, default=None, help="write ppo.json here")
    ap.add_argument("--torch-threads", type=int, default=None, help="torch.set_num_threads")
    args = ap.parse_args(argv)
    if args.torch_threads is not None:
        import torch  # lazy: optional heavy package

        torch.set_num_threads(args.torch_threads)
    seeds = tuple(int(s) for s in args.eval_seeds.split(",") if s.strip())
    run = train_and_evaluate(
        steps=args.steps,
        n_steps=args.n_steps,
        n_epochs=args.epochs,
        learning_rate=args.lr,
        seed=args.seed,
        eval_seeds=seeds,
        budget=args.budget,
    )
    print(run.summary())
    if args.out is not None:
        args.out.mkdir(parents=True, exist_ok=True)
        (args.out / "ppo.json").write_text(json.dumps(run.to_dict(), indent=2) + "\n")
        print(f"wrote {args.out / 'ppo.json'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
