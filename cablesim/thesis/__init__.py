"""``cablesim benchmark thesis``: the protocol of thesis chapters 5 and 6 in simulation.

    from cablesim.thesis import ThesisConfig, run_thesis
    report = run_thesis(ThesisConfig(validation=(1000, 1008), test=(2000, 2012)))

1. Interactions (tables 6.4/6.5): every validation and test scene, with and without the
   neighbour perturbation, one grasp and two actions; for each flow back end the three methods'
   confusion counts over their threshold grids (:mod:`cablesim.thesis.scene`).  ``flows``
   and ``methods`` take any spec of the registries (a plug-in's name or ``MODULE:CLASS``,
   ``docs/plugins.md``): a user's flow back end or method gets its own rows.  Thresholds
   are tuned per beta on validation and scored on test (SPEC section 7).
2. Explorations (tables 6.8/6.9): two grasps on each test scene with motion correlation at the
   thresholds tuned for beta 0.4 (or the thesis's), grades of every proposal, scores of one and
   two grasps at every action threshold.
3. Clips (chapter 5): one hose moved by the gripper, nothing else moving, written as a
   MovingCables dataset; flow back ends thresholded on flow magnitude, tau chosen on the
   validation clips, scored on the test clips with the published protocol.

Every scene is a job (:mod:`cablesim.jobs`): run locally in worker processes or on Ray, one
result file each, resumable; the report (``report.md``, ``report.json``, plots) is recomputed
from the files.  A run killed at any point and started again writes the same files as one that
never stopped, except what records the run itself: ``results/timings.jsonl`` and the date,
machine and run-time lines of ``report.md`` (:mod:`cablesim.provenance`) (``report.json`` holds no time).  ``out/.lock``
refuses a second run into the same folder while one is going.
"""

from __future__ import annotations

import json
import os
import time
from pathlib import Path
from typing import Any

from cablesim import provenance as pv
from cablesim.files import OutputLock, write_text
from cablesim.jobs import Summary, execute, load_results, ray_init, ray_shutdown
from cablesim.jsonutil import json_default
from cablesim.progress import Progress, Say
from cablesim.thesis import report as rp
from cablesim.thesis.config import METHODS, SceneSize, ThesisConfig

THESIS_F04 = (0.18, 0.86)  # table 6.3: c0_min, R2_min for beta 0.4

__all__ = ["SceneSize", "ThesisConfig", "run_thesis"]


def explore_thresholds(cfg: ThesisConfig, rows: list[dict[str, Any]]) -> tuple[float, float, str]:
    """(c0_min, R2_min, where from) for the explorations (module docstring, step 2)."""
    if cfg.explore_thresholds == "tuned":
        p = cfg.explore_perturb if cfg.explore_perturb in cfg.perturb else cfg.perturb[0]
        for r in rows:
            key = (r["flow"], r["perturb"], r["n"], r["method"], r["beta"])
            if key == (cfg.explore_flow, p, 1, "correlation", 0.4) and "params" in r:
                return (
                    r["params"]["c0_min"],
                    r["params"]["r2_min"],
                    f"tuned for beta 0.4 on validation ({cfg.explore_flow}, union)",
                )
    return THESIS_F04[0], THESIS_F04[1], "the thesis's table 6.3 (beta 0.4)"


def run_thesis(
    cfg: ThesisConfig,
    progress: bool = True,
    say: Say | None = None,
    retry_failed: bool = False,
    report_only: bool = False,
) -> dict[str, Any]:
    """Run (or resume) the benchmark of ``cfg`` and write its report to ``cfg.out``
    (``retry_failed``: run the jobs whose recorded outcome is a failure again;
    ``report_only``: run nothing, report from the result files there are)."""
    with OutputLock(cfg.out):  # refused at once while another run writes there
        return _run_thesis(cfg, progress, say, retry_failed, report_only)


def _run_thesis(
    cfg: ThesisConfig,
    progress: bool,
    say: Say | None,
    retry_failed: bool,
    report_only: bool,
) -> dict[str, Any]:
    say = say or Progress("benchmark", progress)
    out = Path(cfg.out)
    results = out / "results"
    out.mkdir(parents=True, exist_ok=True)
    write_text(out / "config.json", json.dumps(cfg.to_dict(), indent=2) + "\n")
    t0 = time.perf_counter()
    summaries: dict[str, Summary] = {}
    started = ray_init(cfg.ray, cfg.workers) if cfg.ray is not None else False
    try:
        jobs = cfg.interaction_jobs()
        say(f"interactions: {len(jobs)} jobs ({cfg.workers} workers, ray {cfg.ray})")
        summaries["interactions"] = execute(
            jobs, results, cfg.workers, cfg.ray, progress, "interactions", retry_failed, report_only
        )
        say(summaries["interactions"].report())
        records = load_results(results, jobs)
        rows = rp.segmentation_rows(
            records, cfg.flows, cfg.perturb, cfg.betas, cfg.action_thresholds, cfg.methods
        )
        doc: dict[str, Any] = {
            "config": cfg.to_dict(),
            "segmentation": [{k: v for k, v in r.items()} for r in rows],
            "thesis_thresholds": rp.thesis_threshold_rows(records, cfg.flows, cfg.perturb),
        }
        explore_records: list[dict[str, Any]] = []
        if cfg.explore:
            c0, r2, source = explore_thresholds(cfg, rows)
            doc["explore_thresholds"] = {"c0_min": c0, "r2_min": r2, "source": source}
            jobs2 = cfg.exploration_jobs(c0, r2)
            say(f"explorations: {len(jobs2)} jobs (c0 {c0:g}, R2 {r2:g}: {source})")
            summaries["explorations"] = execute(
                jobs2,
                results,
                cfg.workers,
                cfg.ray,
                progress,
                "explorations",
                retry_failed,
                report_only,
            )
            say(summaries["explorations"].report())
            explore_records = load_results(results, jobs2)
            doc["grasps"] = rp.grasp_tables(explore_records)
        if cfg.clips:
            jobs3 = cfg.clip_jobs()
            say(f"clips: {len(jobs3)} jobs")
            summaries["clips"] = execute(
                jobs3, results, cfg.workers, cfg.ray, progress, "clips", retry_failed, report_only
            )
            say(summaries["clips"].report())
            doc["clips"] = rp.clip_table(load_results(results, jobs3), cfg.clip_flows)
    finally:
        if started:
            ray_shutdown()
    doc["jobs"] = {
        k: {
            "total": s.total,
            "ok": s.ok,
            "not_run": s.missing,
            "failures": s.failures,
            "outcomes": dict(s.outcomes),
        }
        for k, s in summaries.items()
    }
    doc["wall_s"] = time.perf_counter() - t0
    write_report(cfg, doc, records, out)
    say(f"report: {out / 'report.md'}")
    return doc


def write_report(
    cfg: ThesisConfig, doc: dict[str, Any], records: list[dict[str, Any]], out: Path
) -> None:
    """``report.json``, ``report.md`` and the plots, each written whole (atomically)."""
    rows = doc["segmentation"]
    pr = _plot(out / "pr_curves.png", rp.plot_pr_curves, records, rows)
    dist = _plot(out / "distributions.png", rp.plot_distributions, rows)
    taus = _plot(out / "clip_taus.png", rp.plot_clip_taus, doc.get("clips", {}))
    sc = cfg.scene
    lines = [
        "# The thesis's tables in simulation (`cablesim benchmark thesis`)",
        "",
        f"- date: {pv.utc_date()}; commit {pv.git_commit()}; machine: {pv.machine()}; load "
        f"average {pv.load_average(1)}",
        f"- scenes: validation seeds {cfg.validation[0]}-{cfg.validation[1] - 1}, test seeds "
        f"{cfg.test[0]}-{cfg.test[1] - 1}; {sc.width}x{sc.height}, {sc.hoses} hoses, K_p = "
        f"{sc.periods}, one grasp, two actions (along, across), |D| = 2 cm",
        f"- flows: {', '.join(cfg.flows)}; neighbour perturbation: "
        f"{', '.join('on' if p else 'off' for p in cfg.perturb)}; thresholds tuned per beta on "
        "validation (mean F_beta over scenes, NaN-free), reported on test; undefined precision "
        "(empty prediction) left out of the means, as published",
        *(
            [f"- methods: {', '.join(f'`{m}`' for m in cfg.methods)}"]
            if tuple(cfg.methods) != METHODS
            else []
        ),
        f"- run: {cfg.workers} workers, ray {cfg.ray}; {doc['wall_s']:.0f} s for this call",
        "",
        "## Jobs",
        "",
    ]
    for k, s in doc["jobs"].items():
        fails = ", ".join(f"{o} {len(v)}" for o, v in sorted(s["failures"].items())) or "none"
        extra = f"; {s['not_run']} not run" if s["not_run"] else ""
        lines.append(f"- {k}: {s['ok']} of {s['total']} ok; failed: {fails}{extra}")
    lines += ["", "## Motion segmentation, ablation and correlation (tables 6.3-6.5)", ""]
    lines += rp.segmentation_markdown(rows)
    lines += rp.thesis_thresholds_markdown(doc["thesis_thresholds"])
    if pr:
        lines += [f"![precision-recall]({pr.name})", ""]
    if dist:
        lines += [f"![per-scene distributions]({dist.name})", ""]
    if "grasps" in doc:
        e = doc["explore_thresholds"]
        lines += [
            "## Grasp proposals and two grasps (tables 6.8, 6.9)",
            "",
            f"Explorations of the test scenes: {cfg.explore_grasps} grasps, flow "
            f"`{cfg.explore_flow}`, neighbours {'perturbed' if cfg.explore_perturb else 'still'}, "
            f"motion correlation at c0 {e['c0_min']:g}, R^2 {e['r2_min']:g} ({e['source']}).",
            "",
        ]
        lines += rp.grasp_markdown(doc["grasps"])
    if doc.get("clips"):
        lines += ["## Single moving hose (chapter 5)", ""]
        lines += rp.clip_markdown(doc["clips"])
        if taus:
            lines += [f"![motion threshold]({taus.name})", ""]
    write_text(out / "report.md", "\n".join(lines) + "\n")
    # the run's own wall time is in report.md only, so report.json compares across runs
    kept = {k: v for k, v in doc.items() if k != "wall_s"}
    write_text(
        out / "report.json", json.dumps(_no_nan(kept), indent=1, default=json_default) + "\n"
    )


def _plot(path: Path, plot: Any, *args: Any) -> Path | None:
    """``plot(*args, tmp)`` into a temporary file renamed to ``path``; None (and no stale
    plot of an earlier run left at ``path``) when there is nothing to plot."""
    tmp = path.with_name(f".{path.stem}.{os.getpid()}.tmp{path.suffix}")
    try:
        made = plot(*args, tmp)
        if made is None:
            path.unlink(missing_ok=True)
            return None
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)
    return path


def _no_nan(v: Any) -> Any:
    """NaN (an undefined mean) as null, so the report is strict JSON."""
    if isinstance(v, float) and v != v:
        return None
    if isinstance(v, dict):
        return {k: _no_nan(x) for k, x in v.items()}
    if isinstance(v, list | tuple):
        return [_no_nan(x) for x in v]
    return v
