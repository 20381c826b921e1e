"""Speed and accuracy benchmarks of cablesim, each a module run from the repository root.

Timing scripts (``python -m benchmarks.<name>``): ``bench_sim``, ``bench_render``,
``bench_perception``, ``bench_episode``, ``episode_variants``, ``bench_throughput``,
``bench_solver``, ``bench_env``, ``soak_env``, ``bench_twin``, ``franka_sim_timing``, and the
seed sweep ``seeds`` (its runner is :mod:`cablesim.sweep`), the cable kinds side by side
``cable_kinds``, sleeping islands on and off ``sleep_islands``, and flow back ends on real frames (the published MovingCables videos in
``benchmarks/data/movingcables/``, for evaluation only) ``real_clips``.  Experiments of the thesis's
perception (``python -m benchmarks.experiments.<name>``): ``realistic_flow`` (record, evaluate,
report), ``compare_methods``, ``compare_published``, ``published_reference``.  Each writes its
results, with the run's provenance (:mod:`cablesim.provenance`), to :data:`RESULTS`.
"""

from __future__ import annotations

from pathlib import Path

#: where the results files are written (markdown tables, plots, small JSON summaries)
RESULTS = Path(__file__).resolve().parent / "results"


def write_results(path: Path, text: str) -> None:
    """Write a benchmark's results file (its folder made) and say where."""
    from cablesim.files import write_text

    path.parent.mkdir(parents=True, exist_ok=True)
    write_text(path, text)
    print(f"wrote {path}")
