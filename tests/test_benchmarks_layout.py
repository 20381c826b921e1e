"""``benchmarks/`` stays a package whose scripts run as modules (issue 20): no script edits
``sys.path`` or needs ``noqa: E402``, the raw results files stay out of the repository, and
the realistic-flow summary keeps what its tables show."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
BENCHMARKS = ROOT / "benchmarks"


def _scripts() -> list[Path]:
    return sorted(p for p in BENCHMARKS.rglob("*.py") if "results" not in p.parts)


def test_no_sys_path_edits_and_no_late_imports() -> None:
    for p in _scripts():
        text = p.read_text()
        assert "sys.path.insert" not in text, p
        assert "noqa: E402" not in text, p


def test_every_folder_is_a_package() -> None:
    for p in _scripts():
        assert (p.parent / "__init__.py").is_file(), p


@pytest.mark.parametrize(
    "module", ["benchmarks.seeds", "benchmarks.experiments.realistic_flow", "benchmarks.real_clips"]
)
def test_a_script_runs_as_a_module(module: str) -> None:
    out = subprocess.run(
        [sys.executable, "-m", module, "--help"],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert out.returncode == 0, out.stdout + out.stderr
    assert "usage:" in out.stdout


def test_raw_results_are_not_committed() -> None:
    tracked = subprocess.run(
        ["git", "ls-files", "benchmarks/results"], cwd=ROOT, capture_output=True, text=True
    )
    if tracked.returncode != 0:
        pytest.skip("not a git checkout")
    for name in tracked.stdout.split():
        size = (ROOT / name).stat().st_size if (ROOT / name).exists() else 0
        assert size < 300_000, f"{name}: {size} bytes; raw results are generated, not committed"


def test_the_realistic_flow_summary_leaves_out_the_raw_numbers() -> None:
    from benchmarks.experiments.realistic_flow.__main__ import summary, summary_path

    report = {
        "date": "today",
        "results": {"x": {"test": {"0.4": {"all": {"f": 0.123456789, "per_scene": [{"f": 1}]}}}}},
        "explore": {"big": [1, 2, 3]},
        "timings_cpu_ms_per_frame": {"a": 1.0},
    }
    assert summary(report) == {
        "date": "today",
        "results": {"x": {"test": {"0.4": {"all": {"f": 0.1235}}}}},
    }
    assert summary_path(Path("r/realistic_flow.md")) == Path("r/realistic_flow.summary.json")


def test_realistic_flow_scenes_of_another_kind_or_surface_are_recorded_apart() -> None:
    from benchmarks.experiments.realistic_flow.record import Scene
    from cablesim.sim.config import SceneConfig

    # the default hose on the board keeps the names (and recordings) it always had
    hose = Scene("val", 301, "wood")
    assert hose.name == "val-301-wood-default"
    assert hose.config().scene == SceneConfig(seed=301)
    wire = Scene("test", 905, "solid", "default", "thin_wire", "table")
    assert wire.name == "test-905-solid-default-table-thin_wire"
    assert wire.path != Scene("test", 905, "solid").path
    scene = wire.config().scene
    assert (scene.surface, scene.hoses.kind, scene.table.background) == (
        "table",
        "thin_wire",
        "solid",
    )
    assert scene.seed == 905


def test_recording_a_scene_again_clears_its_cached_statistics(tmp_path, monkeypatch) -> None:
    """``evaluate`` caches perception statistics per scene name; a scene recorded again (here one
    already marked failed is left alone, a new one clears them before it simulates) must not be
    scored with the statistics of its earlier frames."""
    from benchmarks.experiments.realistic_flow import evaluate, record
    from benchmarks.experiments.realistic_flow.record import Scene, record_scene

    scene = Scene("test", 905, "solid", "default", "thin_wire")
    monkeypatch.setattr(record, "CACHE", tmp_path)
    # evaluate caches under the folder record clears
    assert evaluate._stats_path(scene, True, "dis-fine", "arm").is_relative_to(scene.stats_path)
    stale = scene.stats_path / "noisy" / "target.npz"
    stale.parent.mkdir(parents=True)
    stale.write_bytes(b"old")
    scene.failed_path.parent.mkdir(parents=True, exist_ok=True)
    scene.failed_path.write_text("{}")
    assert record_scene(scene)[1] == "failed" and stale.exists()  # not recorded again: kept
    scene.failed_path.unlink()

    def refuse(*args, **kwargs):
        assert not stale.exists(), "the statistics outlived the new recording"
        raise RuntimeError("stop before simulating")

    monkeypatch.setattr("cablesim.sim.session.simulate_episode", refuse)
    assert record_scene(scene)[1] == "failed"
    assert not stale.exists()


def test_the_learned_flow_benchmark_runs_every_learned_spec_with_the_given_weights() -> None:
    """``--weights`` reaches ``learned,gate=null`` too (it once ran the shipped file there)."""
    from benchmarks.learned_flow import with_weights

    assert with_weights("learned", "a.pt") == "learned,weights=a.pt"
    assert with_weights("learned,gate=null", "a.pt") == "learned,weights=a.pt,gate=null"
    assert with_weights("learned,weights=b.pt", "a.pt") == "learned,weights=b.pt"
    assert with_weights("dis", "a.pt") == with_weights("dis", None) == "dis"
    assert with_weights("learned,gate=null", None) == "learned,gate=null"


def test_realistic_flow_statistics_of_a_learned_flow_are_kept_per_weights_file(tmp_path) -> None:
    """The cached statistics of any learned spec are named by the digest of the weights file
    it runs (the shipped default, a shipped model by name, or a path), so other weights never
    read them; other back ends keep their plain names."""
    import hashlib

    from benchmarks.experiments.realistic_flow.evaluate import _flow_dir
    from cablesim.perception.learned import DEFAULT_WEIGHTS, SHIPPED_WEIGHTS

    def sha(p) -> str:
        return hashlib.sha256(p.read_bytes()).hexdigest()[:12]

    assert _flow_dir("dis-fine-board") == "dis-fine-board"
    assert _flow_dir("learned") == f"learned-{sha(DEFAULT_WEIGHTS)}"
    raft = SHIPPED_WEIGHTS["raft"]
    assert _flow_dir("learned,weights=raft") == f"learned,weights=raft-{sha(raft)}"
    a = tmp_path / "a.pt"
    a.write_bytes(b"one")
    assert _flow_dir(f"learned,weights={a},gate=0.7") == f"learned,weights={a},gate=0.7-{sha(a)}"


def test_realistic_flow_runs_any_learned_spec_and_refuses_other_unknown_flows() -> None:
    """``evaluate --learned SPEC``: a learned spec (not only the shipped default) builds the
    learned back end with its options; a name that is neither a known flow nor a learned spec
    is refused."""
    from benchmarks.experiments.realistic_flow.evaluate import flow_for, is_learned
    from cablesim.perception.flow import DISFlow
    from cablesim.perception.learned import SHIPPED_WEIGHTS, LearnedFlow

    est = flow_for("learned,weights=raft,gate=null", None)
    assert isinstance(est, LearnedFlow)
    assert est.weights == SHIPPED_WEIGHTS["raft"] and est.gate is None
    assert isinstance(flow_for("dis-medium", None), DISFlow)
    assert is_learned("learned,weights=raft") and not is_learned("dis-fine")
    with pytest.raises(KeyError, match="unknown flow 'dis-coarse'"):
        flow_for("dis-coarse", None)
