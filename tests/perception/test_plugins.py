"""Plug-in perception: the registries of flow back ends and segmentation methods, specs
(names, entry points, ``MODULE:CLASS`` with parameters), the errors that list the choices, a
user's back end and method (the worked examples of ``docs/plugins.md``, written to a temporary
folder) through the Python API, ``cablesim explore`` and ``cablesim benchmark thesis`` (in
subprocesses with that folder on PYTHONPATH, tiny scenes), and the built-ins' results pinned
across the redesign."""

from __future__ import annotations

import hashlib
import json
import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from cablesim.cli import main
from cablesim.errors import ConfigError, InputError
from cablesim.perception import (
    FLOW_BACKENDS,
    METHODS,
    SEGMENTATION_METHODS,
    DISFlow,
    FlowEstimator,
    SegmentationMethod,
    compute_statistics,
    make_flow,
    make_method,
    masks_from_statistics,
    segment_from_statistics,
    segment_stream,
)
from cablesim.perception.pipeline import params_for_beta
from cablesim.perception.registry import parse_spec
from cablesim.perception.synthetic import Region, SyntheticSpec, synthetic_stream
from cablesim.perception.tuning import threshold_counts, tune_thresholds
from cablesim.policies import ExploreConfig
from cablesim.recording import write_stream
from cablesim.thesis.config import ThesisConfig

DOCS = Path(__file__).resolve().parents[2] / "docs" / "plugins.md"
FLOW = "my_flow:CoarseFarneback"  # the page's worked examples
METHOD = "my_method:MeanMotion"
SCENE = ["--hoses", "3", "--width", "160", "--height", "120", "--periods", "1"]


def doc_files() -> dict[str, str]:
    """The page's code blocks that start with ``# file: NAME``, by file name."""
    blocks = re.findall(r"```python\n(.*?)```", DOCS.read_text(), flags=re.S)
    out = {}
    for b in blocks:
        first = b.splitlines()[0]
        if first.startswith("# file: "):
            out[first[len("# file: ") :].strip()] = b
    return out


def write_examples(folder: Path) -> Path:
    """The page's ``my_flow.py`` and ``my_method.py`` written to ``folder``."""
    files = doc_files()
    assert {"my_flow.py", "my_method.py"} <= set(files), sorted(files)
    for name, text in files.items():
        (folder / name).write_text(text)
    return folder


@pytest.fixture
def examples(tmp_path, monkeypatch):
    """The worked examples importable as ``my_flow`` and ``my_method`` (fresh modules)."""
    folder = tmp_path / "user"
    folder.mkdir()
    write_examples(folder)
    monkeypatch.syspath_prepend(str(folder))
    for name in ("my_flow", "my_method"):
        monkeypatch.delitem(sys.modules, name, raising=False)
    return folder


def _stream(seed: int = 4):
    regions = [
        Region((4, 14, 4, 40), "linear", 0.7, label=0),
        Region((20, 30, 4, 40), "random", 0.8, label=1),
        Region((34, 44, 10, 40), "lag", 0.6, label=2),
    ]
    return synthetic_stream(
        regions, SyntheticSpec(seed=seed, samples_per_period=6, width=96, height=64)
    )


# ----------------------------------------------------------------------------- specs
def test_spec_parses_target_and_json_parameters():
    s = parse_spec("my_flow:CoarseFarneback,scale=0.25,winsize=7,tag=fast,on=true")
    assert s.target == "my_flow:CoarseFarneback" and s.is_path
    assert s.params == {"scale": 0.25, "winsize": 7, "tag": "fast", "on": True}
    assert parse_spec("dis").params == {} and not parse_spec("dis").is_path
    for bad, why in (
        ("", "non-empty"),
        ("dis,preset", "KEY=VALUE"),
        ("dis,preset=fast,preset=medium", "twice"),
        ("a:b:c", "one ':'"),
        (",preset=fast", "empty"),
    ):
        with pytest.raises(InputError, match=why):
            parse_spec(bad)


def test_builtins_are_registered_by_name():
    assert FLOW_BACKENDS.builtins() == [
        "dis",
        "dis-ultrafast",
        "dis-fast",
        "dis-medium",
        "dis-fine",
        "farneback",
        "raft",
        "learned",
        "oracle",
    ]
    assert tuple(SEGMENTATION_METHODS.builtins()) == METHODS
    fast = make_flow("dis-fast")
    assert isinstance(fast, DISFlow) and fast.preset == "fast"
    assert make_flow("dis,preset=medium").describe()["preset"] == "medium"
    assert make_flow("dis", preset="ultrafast").preset == "ultrafast"  # keywords add to a spec
    for name in METHODS:
        m = make_method(name)
        assert isinstance(m, SegmentationMethod) and m.name == name
    # RAFT is registered lazily: its module (and torch) is imported only when it is built
    assert FLOW_BACKENDS.entry("raft").target == "cablesim.perception.raft:RaftFlow"


def test_unknown_names_list_the_choices():
    with pytest.raises(InputError) as e:
        make_flow("magic")
    msg = str(e.value)
    assert msg.startswith("unknown flow back end 'magic'; choose one of dis, dis-ultrafast")
    assert "farneback, raft, learned, oracle" in msg and "MODULE:CLASS" in msg
    assert msg in DOCS.read_text()  # the page shows the message as it is
    with pytest.raises(InputError) as e:
        make_method("magic")
    assert "unknown segmentation method 'magic'; choose one of correlation, segmentation" in str(
        e.value
    )
    # in a config: the project's ConfigError naming the field, with the same choices
    with pytest.raises(
        ConfigError, match=r"^flow: unknown flow back end 'magic'; choose one of dis"
    ):
        ExploreConfig(flow="magic").validate()
    with pytest.raises(ConfigError, match=r"^method: unknown segmentation method 'nope'"):
        ExploreConfig(method="nope").validate()
    with pytest.raises(ConfigError, match=r"^methods: unknown segmentation method 'nope'"):
        ThesisConfig(methods=("correlation", "nope")).validate()
    with pytest.raises(ConfigError, match=r"^flows: unknown flow back end 'magic'"):
        ThesisConfig(flows=("oracle", "magic"), explore_flow="oracle").validate()


def test_bad_targets_and_parameters_are_named(tmp_path, monkeypatch):
    (tmp_path / "not_a_flow.py").write_text("class Thing:\n    pass\n\nvalue = 3\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    with pytest.raises(InputError, match="cannot import module 'no_such_module'"):
        make_flow("no_such_module:Flow")
    with pytest.raises(InputError, match="module 'not_a_flow' has no 'Flow'"):
        make_flow("not_a_flow:Flow")
    with pytest.raises(
        InputError, match="not a subclass of cablesim.perception.flow.FlowEstimator"
    ):
        make_flow("not_a_flow:Thing")
    with pytest.raises(InputError, match="neither a class nor callable"):
        make_method("not_a_flow:value")
    with pytest.raises(InputError, match=r"'dis'.*unexpected keyword argument 'speed'.*preset"):
        make_flow("dis,speed=3")
    with pytest.raises(ConfigError, match=r"flows: flow back end 'raft'.*'checkpoint'"):
        ThesisConfig(flows=("oracle", "raft"), explore_flow="oracle").validate()


def test_entry_point_is_found_by_name(tmp_path, monkeypatch, examples):
    """An installed package's entry points (a faked ``*.dist-info`` on sys.path)."""
    dist = tmp_path / "site" / "cablesim_user_plugins-0.1.dist-info"
    dist.mkdir(parents=True)
    (dist / "METADATA").write_text(
        "Metadata-Version: 2.1\nName: cablesim-user-plugins\nVersion: 0.1\n"
    )
    (dist / "entry_points.txt").write_text(
        "[cablesim.flows]\ncoarse-farneback = my_flow:CoarseFarneback\n\n"
        "[cablesim.methods]\nmean-motion = my_method:MeanMotion\n"
    )
    with pytest.raises(InputError, match="unknown flow back end 'coarse-farneback'"):
        make_flow("coarse-farneback")
    monkeypatch.syspath_prepend(str(tmp_path / "site"))
    assert "coarse-farneback" in FLOW_BACKENDS.names()
    assert FLOW_BACKENDS.names()[: len(FLOW_BACKENDS.builtins())] == FLOW_BACKENDS.builtins()
    flow = make_flow("coarse-farneback,scale=0.25")
    assert type(flow).__name__ == "CoarseFarneback" and flow.scale == 0.25
    assert isinstance(make_method("mean-motion"), SegmentationMethod)
    assert "cablesim-user-plugins" in FLOW_BACKENDS.entry("coarse-farneback").origin
    ExploreConfig(flow="coarse-farneback", method="mean-motion").validate()
    # a name two installed packages register is ambiguous
    other = tmp_path / "site" / "other_plugins-1.0.dist-info"
    other.mkdir()
    (other / "METADATA").write_text("Metadata-Version: 2.1\nName: other-plugins\nVersion: 1.0\n")
    (other / "entry_points.txt").write_text("[cablesim.flows]\ncoarse-farneback = x:Y\n")
    with pytest.raises(InputError, match="registered by several installed packages"):
        make_flow("coarse-farneback")


def test_register_at_run_time():
    class Zero(FlowEstimator):
        name = "zero"

        def compute(self, image1, image2):
            return np.zeros((*image1.shape[:2], 2), np.float32)

    FLOW_BACKENDS.register("zero-test", Zero)
    try:
        with pytest.raises(InputError, match="registered already"):
            FLOW_BACKENDS.register("zero-test", Zero)
        s = _stream()
        stats = compute_statistics(s, "zero-test", methods=("correlation",), pipelined=False)
        assert stats.flow == {"name": "zero"}
        assert not masks_from_statistics(stats, "correlation")[0].any()  # nothing moves
    finally:
        FLOW_BACKENDS.unregister("zero-test")
    assert "zero-test" not in FLOW_BACKENDS.names()


# ----------------------------------------------------------------------------- the examples
def test_doc_examples_run_through_the_python_api(examples):
    flow = make_flow("my_flow:CoarseFarneback,scale=0.5")
    rng = np.random.default_rng(0)
    a = (rng.random((64, 96, 3)) * 255).astype(np.uint8)
    b = np.roll(a, 2, axis=1)  # image2(p) = image1(p - 2 px in x): flow +2 px
    phi = flow.compute(a, b)
    assert phi.shape == (64, 96, 2) and phi.dtype == np.float32
    s = _stream()
    truth = s.target.truth.labels == 0
    stats = compute_statistics(s, "oracle", methods=("correlation", "my_method:MeanMotion"))
    masks = masks_from_statistics(stats, "my_method:MeanMotion")  # a new instance, same key
    assert make_method("my_method:MeanMotion").key == "my_method:MeanMotion"
    assert stats.results["my_method:MeanMotion"].keys() == masks.keys()
    assert sorted(masks) == stats.actions == [0, 1]
    # the moving regions move, the board beside them does not
    union = np.any(list(masks.values()), axis=0)
    assert union[truth].mean() > 0.9 and not union[:, 60:].any()
    # the same through segment_stream, and tuned like the built-ins
    seg = segment_stream(s, "my_method:MeanMotion", flow="oracle", pipelined=False)
    assert seg.method == "my_method:MeanMotion" and np.array_equal(seg.mask(1), union)
    res = tune_thresholds([stats], [truth], "my_method:MeanMotion", (0.4,))
    assert res.method == "my_method:MeanMotion" and set(res.rows[0.4].params) == {"threshold"}
    assert type(res.params(0.4)).__name__ == "MeanMotionParams"
    counts = threshold_counts(stats, truth, "my_method:MeanMotion", 1)
    assert counts.inner_name == "threshold" and counts.outer_name is None
    assert counts.tp.shape == (1, 24)
    # the user's flow through a whole pass
    stats2 = compute_statistics(s, "my_flow:CoarseFarneback", methods=("my_method:MeanMotion",))
    assert stats2.flow == {"name": "coarse-farneback", "scale": 0.5, "winsize": 9}
    assert stats2.n_samples == stats.n_samples


class Count:
    """Counts the flows it is fed."""

    def __init__(self) -> None:
        self.n = 0

    def update(self, job, flow) -> None:
        assert flow.shape == (64, 96, 2)
        self.n += 1

    def result(self) -> int:
        return self.n


def test_a_method_without_a_grid_is_tuned_over_its_own_mask():
    class Everything(SegmentationMethod):
        name = "everything"

        def accumulator(self, ctx, params):
            return Count()

        def masks(self, stats, params):
            assert self.result(stats) > 0
            return {a: np.ones(stats.shape, bool) for a in stats.actions}

    s = _stream()
    truth = s.target.truth.labels == 0
    m = Everything()
    stats = compute_statistics(s, "oracle", methods=(m,), pipelined=False)
    assert stats.results[m.key] == sum(stats.n_samples.values())
    assert m.key.endswith("<locals>.Everything")  # a user's method: keyed by its class
    c = threshold_counts(stats, truth, m, 1)
    assert c.inner_name == "mask" and c.tp.shape == (1, 1)
    voting = truth if stats.support is None else truth & stats.support
    assert c.tp[0, 0] == voting.sum() > 0
    with pytest.raises(InputError, match="computed without the 'everything' method"):
        m.masks(compute_statistics(s, "oracle", methods=("correlation",)), None)


# ----------------------------------------------------------------------------- unchanged
def _h(*arrays) -> str:
    d = hashlib.sha256()
    for a in arrays:
        a = np.ascontiguousarray(a)
        d.update(str(a.dtype).encode())
        d.update(str(a.shape).encode())
        d.update(a.tobytes())
    return d.hexdigest()[:16]


#: the built-ins' results on a synthetic stream with ground-truth flow, computed by the code
#: before the methods became objects (flag-wired ``compute_statistics``)
PINNED = {
    "correlation/0.4": "47e49fb1fed0186d",
    "segmentation/0.4": "1fa359d8c58e3ec5",
    "ablation/0.4": "20853f30ea828f44",
    "published/0.4": "11926b662b8cc7cb",
    "published-segmentation/0.4": "1fa359d8c58e3ec5",
    "published-ablation/0.4": "e18d8a2265156e10",
    "counts/segmentation": "59e6c1e72fd7c1c5",
    "counts/ablation": "4656cd377e8cf390",
    "counts/correlation": "b0167efb49d86795",
    "alone/published-segmentation": "2d5166e1c8bc0e55",
    "alone/published-ablation": "49d6770288455ab0",
}


@pytest.mark.parametrize("pipelined", [False, True])
def test_builtin_results_unchanged(pipelined):
    s = _stream()
    truth = s.target.truth.labels == 0
    stats = compute_statistics(s, "oracle", methods=METHODS, pipelined=pipelined)
    got = {}
    for m in METHODS:
        seg = segment_from_statistics(stats, m, params_for_beta(m, 0.4))
        got[f"{m}/0.4"] = _h(
            seg.votes,
            *[seg.masks[a] for a in sorted(seg.masks)],
            *[seg.c0[a] for a in sorted(seg.c0)],
            *[seg.r2[a] for a in sorted(seg.r2)],
        )
    for m in ("segmentation", "ablation", "correlation"):
        c = threshold_counts(stats, truth, m, 1)
        got[f"counts/{m}"] = _h(c.tp, c.fp)
    for ms in (("published-segmentation",), ("segmentation", "published-ablation")):
        alone = compute_statistics(s, "oracle", methods=ms, pipelined=pipelined)
        got[f"alone/{ms[-1]}"] = _h(segment_from_statistics(alone, ms[-1]).votes)
    assert got == PINNED
    assert stats.n_samples == {0: 13, 1: 13}


# ----------------------------------------------------------------------------- commands


def _run(tmp_path, *argv: str) -> subprocess.CompletedProcess:
    user = tmp_path / "user"
    user.mkdir(exist_ok=True)
    write_examples(user)
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(p for p in (str(user), env.get("PYTHONPATH", "")) if p)
    return subprocess.run(
        [sys.executable, "-m", "cablesim.cli", *argv],
        capture_output=True,
        text=True,
        env=env,
        cwd=tmp_path,
        timeout=1500,
    )


def test_a_module_that_is_not_there_fails_before_anything_is_built(tmp_path, capsys):
    out = tmp_path / "run"
    assert main(["explore", "--flow", "my_missing_flow:Flow", "--out", str(out), *SCENE]) == 2
    err = capsys.readouterr().err
    assert "flow: flow back end 'my_missing_flow:Flow': cannot import module" in err
    assert main(["explore", "--method", "magic", "--out", str(out), *SCENE]) == 2
    err = capsys.readouterr().err
    assert "method: unknown segmentation method 'magic'; choose one of correlation" in err
    assert not out.exists()


def test_segment_command_runs_a_user_flow_and_method(tmp_path, examples):
    rec = write_stream(_stream(), tmp_path / "rec")
    out = tmp_path / "seg"
    argv = ["segment", str(rec), "--out", str(out), "--quiet", "--flow", "oracle"]
    assert main([*argv, "--method", METHOD]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["method"] == METHOD and summary["params"] == {"threshold": 1.0}
    assert np.load(out / "votes.npy").any()
    assert json.loads((out / "scores.json").read_text())["union"]["recall"] > 0.9
    out2 = tmp_path / "seg2"
    argv = ["segment", str(rec), "--out", str(out2), "--quiet", "--flow", FLOW + ",scale=0.25"]
    assert main([*argv, "--method", "correlation"]) == 0
    summary = json.loads((out2 / "summary.json").read_text())
    assert summary["flow"] == {"name": "coarse-farneback", "scale": 0.25, "winsize": 9}


@pytest.mark.slow
def test_explore_runs_a_user_flow_and_method(tmp_path):
    out = tmp_path / "ex"
    r = _run(
        tmp_path,
        "explore", "--seed", "2", "--hose", "1", *SCENE, "--grasps", "1",
        "--flow", FLOW, "--method", METHOD, "--out", str(out), "--quiet",
    )  # fmt: skip
    assert r.returncode == 0, r.stderr
    assert f"method {METHOD}, flow {FLOW}" in r.stdout
    metrics = json.loads((out / "metrics.json").read_text())
    assert (metrics["flow"], metrics["method"]) == (FLOW, METHOD)
    first = metrics["interactions"][0]
    assert first["success"] and set(first["scores"]) >= {"precision", "recall", "iou"}
    assert (out / "interaction0_votes.npy").is_file() and (out / "interaction0_flow.png").is_file()
    saved = json.loads((out / "config.json").read_text())
    assert (saved["flow"], saved["method"]) == (FLOW, METHOD)  # and reruns with --config


@pytest.mark.slow
def test_thesis_benchmark_tables_for_a_user_flow_and_method(tmp_path):
    out = tmp_path / "thesis"
    r = _run(
        tmp_path,
        "benchmark", "thesis", "--validation", "0:1", "--test", "1:2", "--perturb", "on",
        *SCENE, "--no-explore", "--clip-validation", "3000:3001", "--clip-test", "4000:4001",
        "--flows", "oracle", FLOW, "--methods", "correlation", METHOD,
        "--clip-flows", FLOW, "--workers", "1", "--quiet", "--out", str(out),
    )  # fmt: skip
    assert r.returncode == 0, r.stderr
    doc = json.loads((out / "report.json").read_text())
    assert doc["jobs"]["interactions"]["ok"] == 2 and doc["jobs"]["clips"]["ok"] == 2
    rows = doc["segmentation"]
    # every flow x method pair has tuned rows scored on the test scene, the user's ones too
    pairs = {(r["flow"], r["method"]) for r in rows if r.get("f") is not None}
    assert pairs == {(f, m) for f in ("oracle", FLOW) for m in ("correlation", METHOD)}
    mine = [r for r in rows if r["method"] == METHOD and r["beta"] == 0.4 and r["n"] == 1]
    assert {r["flow"] for r in mine} == {"oracle", FLOW}
    assert all(set(r["params"]) == {"threshold"} for r in mine)
    assert doc["clips"][FLOW]["images"] > 0  # chapter 5's table for the user's flow
    md = (out / "report.md").read_text()
    assert f"flow `{FLOW}`" in md and f"| {METHOD} | 0.4 |" in md
    assert f"| {FLOW} |" in md and "| Motion correlation | 0.4 |" in md
    assert f"- methods: `correlation`, `{METHOD}`" in md
