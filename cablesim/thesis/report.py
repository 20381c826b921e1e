"""Aggregates of ``cablesim benchmark thesis`` recomputed from the per-scene result files:
tuning on validation and scores on test (SPEC section 7), the tables beside the thesis's
numbers (markdown and JSON), and the plots (precision-recall curves, per-scene distributions,
the motion threshold of chapter 5)."""

from __future__ import annotations

from collections import Counter
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import matplotlib
import matplotlib.pyplot as plt
import numpy as np

from cablesim.perception.metrics import nanmean
from cablesim.perception.tuning import ThresholdCounts, tune_counts
from cablesim.thesis import reference as ref

METHODS = ("segmentation", "ablation", "correlation")
N_NAME = {1: "union", 2: "intersection"}
COLOURS = {"segmentation": "tab:orange", "ablation": "tab:green", "correlation": "tab:blue"}
OTHER_COLOURS = ("tab:red", "tab:purple", "tab:brown", "tab:pink", "tab:olive", "tab:cyan")


def method_name(method: str) -> str:
    """A method's name in the tables: the thesis's for its own, else the spec itself."""
    return ref.METHOD_NAMES.get(method, method)


def _colour(method: str, methods: Sequence[str]) -> str:
    if method in COLOURS:
        return COLOURS[method]
    others = [m for m in methods if m not in COLOURS]
    return OTHER_COLOURS[others.index(method) % len(OTHER_COLOURS)]


def _f(v: Any) -> float:
    return float("nan") if v is None else float(v)


def _fmt(v: float | None, nd: int = 3) -> str:
    if v is None or (isinstance(v, float) and np.isnan(v)):
        return "-"
    return f"{v:.{nd}f}"


def _ok(records: Sequence[dict[str, Any]], **match: Any) -> list[dict[str, Any]]:
    out = []
    for r in records:
        if r["status"] != "ok":
            continue
        if all(r["params"].get(k) == v for k, v in match.items()):
            out.append(r)
    return out


# --------------------------------------------------------------------------- tables 6.4 / 6.5
def _counts(
    records: Sequence[dict[str, Any]], flow: str, method: str, n: int
) -> list[ThresholdCounts]:
    return [
        ThresholdCounts.from_dict(r["result"]["flows"][flow]["counts"][method][str(n)])
        for r in records
        if flow in r["result"]["flows"] and method in r["result"]["flows"][flow]["counts"]
    ]


def segmentation_rows(
    records: Sequence[dict[str, Any]],
    flows: Sequence[str],
    perturbs: Sequence[bool],
    betas: Sequence[float],
    ns: Sequence[int] = (1, 2),
    methods: Sequence[str] = METHODS,
) -> list[dict[str, Any]]:
    """One row per flow, perturbation, action threshold, method and beta: thresholds tuned on
    the validation scenes, the means over the test scenes at them, and the per-scene values."""
    rows = []
    for flow in flows:
        for p in perturbs:
            val = _ok(records, split="validation", perturb=p)
            test = _ok(records, split="test", perturb=p)
            for n in ns:
                for method in methods:
                    cv = _counts(val, flow, method, n)
                    ct = _counts(test, flow, method, n)
                    for beta in betas:
                        row: dict[str, Any] = {
                            "flow": flow,
                            "perturb": p,
                            "n": n,
                            "method": method,
                            "beta": beta,
                            "validation_scenes": len(cv),
                            "test_scenes": len(ct),
                        }
                        if cv:
                            i, j, fval = tune_counts(cv, beta)
                            row["params"] = cv[0].params(i, j)
                            row["validation_f"] = fval
                            if ct:
                                per = [c.scores(beta) for c in ct]
                                vals = {
                                    k: [float(s[q][i, j]) for s in per]
                                    for q, k in enumerate(("precision", "recall", "iou", "f"))
                                }
                                row.update({k: nanmean(v) for k, v in vals.items()})
                                row["per_scene"] = {
                                    k: [None if np.isnan(x) else x for x in v]
                                    for k, v in vals.items()
                                }
                        rows.append(row)
    return rows


def thesis_threshold_rows(
    records: Sequence[dict[str, Any]], flows: Sequence[str], perturbs: Sequence[bool]
) -> list[dict[str, Any]]:
    """Test means at the thesis's own thresholds (SPEC section 8's per-beta table), untuned."""
    rows = []
    for flow in flows:
        for p in perturbs:
            test = [
                r for r in _ok(records, split="test", perturb=p) if flow in r["result"]["flows"]
            ]
            if not test:
                continue
            for method in ("segmentation", "correlation"):
                if not all(method in r["result"]["flows"][flow]["thesis_thresholds"] for r in test):
                    continue  # not among the benchmark's methods
                for beta in ("1", "0.5", "0.4", "0.3", "0.2", "0.1"):
                    for n in ("1", "2"):
                        s = [
                            r["result"]["flows"][flow]["thesis_thresholds"][method][beta][n]
                            for r in test
                        ]
                        rows.append(
                            {
                                "flow": flow,
                                "perturb": p,
                                "method": method,
                                "beta": float(beta),
                                "n": int(n),
                                "precision": nanmean(_f(x["precision"]) for x in s),
                                "recall": nanmean(_f(x["recall"]) for x in s),
                                "f": nanmean(_f(x[f"f{beta}"]) for x in s),
                                "iou": nanmean(_f(x["iou"]) for x in s),
                                "test_scenes": len(s),
                            }
                        )
    return rows


def _reference_row(method: str, beta: float, n: int) -> tuple[float, ...] | None:
    table = ref.TABLE_6_4 if n == 1 else ref.TABLE_6_5
    return table.get((method, beta))


def _params_text(p: dict[str, float] | None) -> str:
    if not p:
        return "-"
    names = {"tau_v": "tau_v", "c0_min": "c0", "r2_min": "R2", "std_min": "std"}
    return ", ".join(f"{names.get(k, k)} {v:g}" for k, v in sorted(p.items()))


def segmentation_markdown(rows: list[dict[str, Any]]) -> list[str]:
    lines: list[str] = []
    keys = list(dict.fromkeys((r["flow"], r["perturb"], r["n"]) for r in rows))
    for flow, p, n in keys:
        sel = [r for r in rows if (r["flow"], r["perturb"], r["n"]) == (flow, p, n)]
        table = "6.4" if n == 1 else "6.5"
        nv, nt = sel[0]["validation_scenes"], sel[0]["test_scenes"]
        lines += [
            f"### Table {table} ({N_NAME[n]} of the two actions): flow `{flow}`, neighbours "
            f"{'perturbed' if p else 'not perturbed'} ({nv} validation / {nt} test scenes)",
            "",
            "| method | beta | thresholds (validation) | recall | precision | F_beta | IoU "
            "| thesis recall | thesis precision | thesis F_beta | thesis IoU |",
            "|---|---|---|---|---|---|---|---|---|---|---|",
        ]
        for beta in sorted({r["beta"] for r in sel}, reverse=True):
            for r in sel:
                if r["beta"] != beta:
                    continue
                t = _reference_row(r["method"], beta, n)
                th = [_fmt(x, 4) for x in t] if t else ["-"] * 4
                lines.append(
                    f"| {method_name(r['method'])} | {beta:g} | {_params_text(r.get('params'))} "
                    f"| {_fmt(r.get('recall'))} | {_fmt(r.get('precision'))} | {_fmt(r.get('f'))} "
                    f"| {_fmt(r.get('iou'))} | {' | '.join(th)} |"
                )
        lines.append("")
    return lines


def thesis_thresholds_markdown(rows: list[dict[str, Any]]) -> list[str]:
    if not rows:
        return []
    lines = [
        "### At the thesis's thresholds (SPEC section 8, not tuned here), test scenes",
        "",
        "| flow | neighbours | method | beta | votes | recall | precision | F_beta | IoU |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(
            f"| {r['flow']} | {'perturbed' if r['perturb'] else 'still'} "
            f"| {method_name(r['method'])} | {r['beta']:g} | {N_NAME[r['n']]} "
            f"| {_fmt(r['recall'])} | {_fmt(r['precision'])} | {_fmt(r['f'])} | {_fmt(r['iou'])} |"
        )
    return [*lines, ""]


# --------------------------------------------------------------------------- tables 6.8 / 6.9
def grasp_tables(records: Sequence[dict[str, Any]]) -> dict[str, Any]:
    ok = [r for r in records if r["status"] == "ok"]
    grades: Counter = Counter()
    for r in records:  # proposals of failed explorations count too
        grades.update(r["result"].get("proposal_grades", {}))
    two = [r for r in ok if "two_grasps" in r["result"]]
    rows = {}
    for g, n in ref.TABLE_6_9:
        src = [r["result"]["one_grasp" if g == 1 else "two_grasps"].get(str(n)) for r in two]
        src = [s for s in src if s is not None]
        rows[f"{g}@{n}"] = {
            "grasps": g,
            "n": n,
            "recall": nanmean(_f(s["recall"]) for s in src) if src else None,
            "precision": nanmean(_f(s["precision"]) for s in src) if src else None,
            "f": nanmean(_f(s["f0.4"]) for s in src) if src else None,
            "iou": nanmean(_f(s["iou"]) for s in src) if src else None,
            "scenes": len(src),
        }
    return {
        "explorations": len(records),
        "with_a_grasp": len(ok),
        "with_two_grasps": len(two),
        "grades": dict(grades),
        "rows": rows,
    }


def grasp_markdown(t: dict[str, Any]) -> list[str]:
    total = sum(t["grades"].values())
    lines = [
        f"### Table 6.8: grasp proposals ({t['explorations']} explorations of the test scenes)",
        "",
        "| proposal | count | % | thesis count | thesis % |",
        "|---|---|---|---|---|",
        f"| total | {total} | 100 | 54 | 100 |",
    ]
    for g, (c, pct) in ref.TABLE_6_8.items():
        k = t["grades"].get(g, 0)
        share = f"{100 * k / total:.0f}" if total else "-"
        lines.append(f"| {g.replace('_', ' ')} | {k} | {share} | {c} | {pct} |")
    lines += [
        "",
        f"### Table 6.9: one and two grasps ({t['with_two_grasps']} explorations with two "
        "successful grasps; motion correlation)",
        "",
        "| grasps @ action thr. | recall | precision | F_0.4 | IoU | thesis recall "
        "| thesis precision | thesis F_0.4 | thesis IoU |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for (g, n), th in ref.TABLE_6_9.items():
        r = t["rows"][f"{g}@{n}"]
        name = f"{'One grasp' if g == 1 else 'Two grasps'} @ {n}"
        lines.append(
            f"| {name} | {_fmt(r['recall'])} | {_fmt(r['precision'])} | {_fmt(r['f'])} "
            f"| {_fmt(r['iou'])} | {' | '.join(_fmt(x, 4) for x in th)} |"
        )
    return [*lines, ""]


# --------------------------------------------------------------------------- chapter 5
def clip_table(records: Sequence[dict[str, Any]], flows: Sequence[str]) -> dict[str, Any]:
    """Motion threshold tau per back end chosen by the mean IoU over all validation images,
    then recall, precision, IoU and EPE over all test images (the MovingCables protocol)."""
    out: dict[str, Any] = {}
    for flow in flows:
        val = [
            r["result"]["flows"][flow]
            for r in _ok(records, split="validation")
            if flow in r["result"]["flows"]
        ]
        test = [
            r["result"]["flows"][flow]
            for r in _ok(records, split="test")
            if flow in r["result"]["flows"]
        ]
        if not val:
            continue
        taus = list(val[0]["taus"])
        val_iou = {t: nanmean(_f(x) for v in val for x in v["taus"][t]["iou"]) for t in taus}
        best = max(taus, key=lambda t: -1.0 if np.isnan(val_iou[t]) else val_iou[t])
        row: dict[str, Any] = {
            "tau": float(best),
            "validation_iou": val_iou,
            "validation_clips": len(val),
            "test_clips": len(test),
        }
        if test:
            for k in ("recall", "precision", "iou"):
                row[k] = nanmean(_f(x) for v in test for x in v["taus"][best][k])
            row["epe"] = float(np.mean([x for v in test for x in v["epe"]]))
            row["images"] = sum(len(v["epe"]) for v in test)
        out[flow] = row
    return out


def clip_markdown(t: dict[str, Any]) -> list[str]:
    if not t:
        return []
    lines = [
        "### Chapter 5 (table 5.1): one moving hose, flow thresholded on its magnitude, "
        "MovingCables protocol (normal-flow ground truth, the arm masked as the stick)",
        "",
        "| flow back end | tau (validation) | recall | precision | IoU | EPE (px) | clips val/test |",
        "|---|---|---|---|---|---|---|",
    ]
    for flow, r in t.items():
        lines.append(
            f"| {flow} | {r['tau']:g} | {_fmt(r.get('recall'))} | {_fmt(r.get('precision'))} "
            f"| {_fmt(r.get('iou'))} | {_fmt(r.get('epe'), 2)} | {r['validation_clips']}/{r['test_clips']} |"
        )
    lines += [
        "",
        "Thesis (real clips, table 5.1):",
        "",
        "| method | tau | recall | precision | IoU | EPE (px) |",
        "|---|---|---|---|---|---|",
    ]
    for name, (rc, pr, iou, epe, tau) in ref.TABLE_5_1.items():
        lines.append(f"| {name} | {tau:g} | {rc:.4f} | {pr:.4f} | {iou:.4f} | {epe:.2f} |")
    return [*lines, ""]


# --------------------------------------------------------------------------- plots
def plot_pr_curves(
    records: Sequence[dict[str, Any]], rows: list[dict[str, Any]], path: Path
) -> Path | None:
    """Mean precision against mean recall over the test scenes as each method's threshold
    sweeps (correlation: R^2 at the c0 tuned for beta 0.4), union; the thesis's beta 0.4
    points as stars."""

    matplotlib.use("Agg")

    keys = sorted(
        {(r["flow"], r["perturb"]) for r in rows if r["n"] == 1}, key=lambda k: (k[0], not k[1])
    )
    if not keys:
        return None
    fig, axes = plt.subplots(1, len(keys), figsize=(5 * len(keys), 4.6), squeeze=False)
    methods = list(dict.fromkeys(r["method"] for r in rows))
    for ax, (flow, p) in zip(axes[0], keys, strict=True):
        test = [r for r in _ok(records, split="test", perturb=p) if flow in r["result"]["flows"]]
        for method in methods:
            colour = _colour(method, methods)
            tuned = [
                r
                for r in rows
                if (r["flow"], r["perturb"], r["n"], r["method"], r["beta"])
                == (flow, p, 1, method, 0.4)
            ]
            if not test or not tuned or "params" not in tuned[0]:
                continue
            cs = [
                ThresholdCounts.from_dict(r["result"]["flows"][flow]["counts"][method]["1"])
                for r in test
            ]
            i = 0
            if cs[0].outer_name is not None:
                i = int(np.argmin(np.abs(cs[0].outer - tuned[0]["params"][cs[0].outer_name])))
            P = np.array([c.scores(0.4)[0][i] for c in cs])
            R = np.array([c.scores(0.4)[1][i] for c in cs])
            with np.errstate(all="ignore"):
                mp = np.array([nanmean(P[:, j]) for j in range(P.shape[1])])
                mr = np.array([nanmean(R[:, j]) for j in range(R.shape[1])])
            ax.plot(mr, mp, "-", color=colour, label=method_name(method))
            ax.plot(
                [tuned[0].get("recall", np.nan)],
                [tuned[0].get("precision", np.nan)],
                "o",
                color=colour,
            )
            th = ref.TABLE_6_4.get((method, 0.4))
            if th:
                ax.plot([th[0]], [th[1]], "*", ms=12, color=colour, mec="k")
        ax.set_title(
            f"flow {flow}, neighbours {'perturbed' if p else 'still'}\n({len(test)} test scenes, union)"
        )
        ax.set_xlabel("recall (mean over scenes)")
        ax.set_ylabel("precision (mean over scenes)")
        ax.set_xlim(0, 1)
        ax.set_ylim(0, 1.02)
        ax.grid(alpha=0.3)
        ax.legend(
            fontsize=8, loc="lower left", title="o tuned (beta 0.4), * thesis", title_fontsize=7
        )
    fig.suptitle("Precision-recall over the threshold sweep (test scenes)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def _short(spec: str) -> str:
    """A box label: a built-in method's first four letters, a spec's class name."""
    if spec in COLOURS:
        return spec[:4]
    return spec.split(",")[0].split(":")[-1][:14]


def plot_distributions(rows: list[dict[str, Any]], path: Path, beta: float = 0.4) -> Path | None:
    """Per-scene F_beta, precision and recall on the test scenes at the thresholds tuned for
    ``beta`` (union): one box per method and setting."""

    matplotlib.use("Agg")

    sel = [r for r in rows if r["n"] == 1 and r["beta"] == beta and "per_scene" in r]
    if not sel:
        return None
    metrics = ("f", "precision", "recall")
    fig, axes = plt.subplots(1, 3, figsize=(15, 4.8))
    labels = [
        f"{_short(r['method'])}\n{_short(r['flow'])}\n{'pert.' if r['perturb'] else 'still'}"
        for r in sel
    ]
    for ax, k in zip(axes, metrics, strict=True):
        data = [[x for x in r["per_scene"][k] if x is not None] for r in sel]
        ax.boxplot(data, tick_labels=labels, showmeans=True)
        ax.set_title(
            {"f": f"F_{beta:g}", "precision": "precision", "recall": "recall"}[k]
            + " per test scene"
        )
        ax.set_ylabel(k if k != "f" else f"F_{beta:g}")
        ax.set_xlabel("method / flow / neighbours")
        ax.set_ylim(-0.02, 1.02)
        ax.tick_params(axis="x", labelsize=7)
        ax.grid(alpha=0.3, axis="y")
    fig.suptitle(f"Per-scene distributions at the thresholds tuned for beta {beta:g} (union)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def plot_clip_taus(t: dict[str, Any], path: Path) -> Path | None:

    matplotlib.use("Agg")

    if not t:
        return None
    fig, ax = plt.subplots(figsize=(6, 4.2))
    for flow, r in t.items():
        taus = [float(k) for k in r["validation_iou"]]
        ax.plot(taus, list(r["validation_iou"].values()), "o-", label=f"{flow} (tau* {r['tau']:g})")
    ax.set_xscale("log")
    ax.set_xlabel("motion threshold tau (px)")
    ax.set_ylabel("mean IoU over validation images")
    ax.set_title("Chapter 5: choosing the motion threshold on validation clips")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
