"""The same seeds give the same numbers, bit for bit (issue 20): pinned result hashes.

Each case runs ``cablesim explore`` in-process, as a user runs it, on a tiny scene (160x120,
one period per action, ``--record``) and compares SHA-256 hashes of:

- ``frames``: the RGB and depth bytes of every kept frame of every recorded interaction
  (``recordings/interaction{k}``, target frame last), in order;
- ``votes``: every ``*_votes.npy`` the run wrote (each interaction's and the merged votes;
  none when no interaction succeeded);
- ``metrics``: ``metrics.json`` without its wall-clock fields (every ``timings_s``) and without
  ``config``, with the command's exit code;
- ``config``: the ``config`` of ``metrics.json`` alone, so that a new layout of the configuration
  shows as a change of this hash only, the results' hashes staying as they were.

The hashes are of this project's machines (MuJoCo's CPU physics, Mesa's software renderer) and
are kept per platform (:func:`cablesim.provenance.float_platform`, the CPU vendor): on an Intel
Xeon the same seeds gave the same votes as on an AMD EPYC but floats that differ in the last
digits and other pixels (MuJoCo, NumPy and llvmpipe take vendor-specific SIMD paths), so a
platform with no pins skips the comparison and says so.  Where one CPU family of a vendor
differs from the vendor's pins it is pinned on its own, and the pins are looked up under
:func:`cablesim.provenance.float_platforms`, the most specific name first.  ``config`` is the same everywhere.

Regenerate the hashes with ``.venv/bin/python tests/test_pinned_results.py`` on a machine of
each platform (prints this platform's ``PINNED`` entry and ``PINNED_CONFIG`` to paste below) and the README demo's metrics with
``.venv/bin/python tests/test_pinned_results.py --demo`` (about 2-5 minutes; writes
``tests/data/readme_demo_metrics.json``).  A change of any hash or of the demo's metrics needs a
reason in the commit message (which change of behaviour, and why it is wanted).

The README demo (``cablesim explore --seed 0 --out runs/demo``) is too slow for every run; its
metrics (timings removed) are recorded in ``tests/data/readme_demo_metrics.json`` and compared
on demand: ``CABLESIM_PIN_DEMO=1 .venv/bin/python -m pytest -q tests/test_pinned_results.py``.
"""

from __future__ import annotations

import hashlib
import json
import os
import re
import sys
import tempfile
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import cablesim  # noqa: F401  (selects the headless GL back end before mujoco)
from cablesim.provenance import float_platform, float_platforms

TINY = ["--width", "160", "--height", "120", "--periods", "1", "--quiet", "--record"]

#: case -> the explore command line (``--out`` and ``TINY`` added)
CASES: dict[str, list[str]] = {
    "seed3_sampler": ["--seed", "3", "--hoses", "2", "--grasps", "1"],
    "seed2_push": ["--seed", "2", "--hoses", "3", "--grasps", "1", "--strategy", "push"],
    # a grasp that never holds (a hold check no grasp passes): retries, then grasp_not_held
    "seed1_not_held": ["--seed", "1", "--hoses", "3", "--grasps", "1"]
    + ["--set", "episode.interaction.grasp.hold_tolerance=1e-6"],
}

#: the hashes both x86_64 platforms gave on 2026-12-07 (an Intel Xeon, then an AMD EPYC after
#: issue 21's physics changes had left AMD unpinned): the same, bit for bit; a platform that
#: gives others on re-pinning gets an entry of its own
_X86_64_PINS: dict[str, dict[str, str]] = {
    "seed1_not_held": {
        "frames": "1a1718fdce1999e679160b62c3bc964adfdde7c0e5bdd773443dde234acf0cf4",
        "votes": "e3b0c44298fc1c149afbf4c8996fb92427ae41e4649b934ca495991b7852b855",
        "metrics": "223d1b7029023cb1294ddf94f57faaffec6df7d869848a9719865eceb291d28b",
    },
    "seed2_push": {
        "frames": "b1f6395ea5bb864305258da75dcafdef9753226c87013ba9f048bdb5f6b66566",
        "votes": "8e6714a0a14cc5c3118743ca99f127f8e7b58cbcf650537a647ceb69ddf4d749",
        "metrics": "7bf2603ecbd47533f823db7883a0d324f50f27c99b62bff1d1f80d4de553c557",
    },
    "seed3_sampler": {
        "frames": "9df8623bb45bc560e30376911a5e4de6a3b5a1f81eb01bfb30c4edc86cec1cb2",
        "votes": "677326d3396a7a3149cc7d2c67ea52db873803b399226f693143a83b2f713ecc",
        "metrics": "0cad518019e6e7dd00e080fa06d541570ff6f4c6086b9548fa921bfdb0c46e69",
    },
}
#: platform (:func:`cablesim.provenance.float_platform`) -> case -> SHA-256 of the frames, votes
#: and metrics: the floats of one seed's run agree bit for bit on one platform only (regenerate:
#: see the module docstring)
PINNED: dict[str, dict[str, dict[str, str]]] = {
    "x86_64 AuthenticAMD": _X86_64_PINS,
    "x86_64 GenuineIntel": _X86_64_PINS,
    # an AMD EPYC of CPU family 26, 2026-12-08: the same frames and votes for seeds 1 and 2 but
    # other metrics floats, and other frames for seed 3, at the commit whose AMD and Intel
    # pins above had agreed (2981e84), so the difference is the CPU's, not the code's
    "x86_64 AuthenticAMD family 26": {
        "seed1_not_held": {
            "frames": "1a1718fdce1999e679160b62c3bc964adfdde7c0e5bdd773443dde234acf0cf4",
            "votes": "e3b0c44298fc1c149afbf4c8996fb92427ae41e4649b934ca495991b7852b855",
            "metrics": "fd4460ec1e0f7f89bf7f4371c3ec67dcd5afd4b8d9ba62f4637032d7716cb71a",
        },
        "seed2_push": {
            "frames": "b1f6395ea5bb864305258da75dcafdef9753226c87013ba9f048bdb5f6b66566",
            "votes": "8e6714a0a14cc5c3118743ca99f127f8e7b58cbcf650537a647ceb69ddf4d749",
            "metrics": "9c72e5a5308cd1d30e5f9e3e7a4f2c8916f177e9469a0f6062baeb85ebd55cd2",
        },
        "seed3_sampler": {
            "frames": "4695e2e23c8187e61a574b95a7d325a46f73591815835e614ee9b613dddc1cd8",
            "votes": "677326d3396a7a3149cc7d2c67ea52db873803b399226f693143a83b2f713ecc",
            "metrics": "77597b6b921ded6d383ee103be9b80932dbd104a3f8dd17e53d0f04c65839d3c",
        },
    },
}
#: case -> SHA-256 of the run's ``config`` (the same on every platform)
PINNED_CONFIG: dict[str, str] = {
    "seed1_not_held": "4bf1e9e7d8ec0a5f44cfbf6a816bee63797f6654bb4fc3617b97e2ebae47776a",
    "seed2_push": "2f26394a0f84a2c156629f0f3b2e22926bc6159f73bb42720fb7ef1b09deb17b",
    "seed3_sampler": "df8a09ef3b806381fd053f864468978dea021ac634563bcf37de6cc7a67c5c47",
}
DEMO_ARGS = ["--seed", "0"]  # the README's demo: cablesim explore --seed 0 --out runs/demo
DEMO_METRICS = Path(__file__).parent / "data" / "readme_demo_metrics.json"
DEMO_PLATFORM = "x86_64 GenuineIntel"  # where DEMO_METRICS was written


# ---------------------------------------------------------------------- hashing
def without_timings(doc: Any) -> Any:
    """``doc`` without the wall-clock fields (every ``timings_s``, at any depth)."""
    if isinstance(doc, dict):
        return {k: without_timings(v) for k, v in doc.items() if k != "timings_s"}
    if isinstance(doc, list):
        return [without_timings(v) for v in doc]
    return doc


def json_digest(doc: Any) -> str:
    text = json.dumps(doc, sort_keys=True, separators=(",", ":"), allow_nan=True)
    return hashlib.sha256(text.encode()).hexdigest()


def _array_update(h: Any, name: str, a: np.ndarray) -> None:
    a = np.ascontiguousarray(a)
    h.update(f"{name}:{a.dtype.str}:{a.shape};".encode())
    h.update(a.tobytes())


def frames_digest(recordings: Path) -> str:
    """RGB and depth of every frame of every recorded interaction, in interaction order."""
    from cablesim.recording import Recording

    h = hashlib.sha256()
    dirs = sorted(recordings.glob("interaction*"), key=lambda p: int(p.name[len("interaction") :]))
    assert dirs, f"no recordings in {recordings}"
    for d in dirs:
        rec = Recording(d)
        h.update(f"{d.name}:{len(rec)}:{rec.complete};".encode())
        for i, f in enumerate(rec):
            _array_update(h, f"rgb{i}", f.rgb)
            _array_update(h, f"depth{i}", f.depth)
    return h.hexdigest()


def votes_digest(out: Path) -> str:
    h = hashlib.sha256()
    for p in sorted(out.glob("*_votes.npy")):  # none when no interaction succeeded
        _array_update(h, p.name, np.load(p, allow_pickle=False))
    return h.hexdigest()


def run_explore(args: list[str], out: Path) -> dict[str, Any]:
    """``cablesim explore ARGS --out OUT`` in-process: its metrics.json and, as
    ``exit_code``, what the command returned (1 when no interaction succeeded)."""
    from cablesim.cli import main

    code = main(["explore", *args, "--out", str(out)])
    return {**json.loads((out / "metrics.json").read_text()), "exit_code": code}


def demo_metrics(out: Path) -> dict[str, Any]:
    """The README demo's metrics.json, timings removed."""
    metrics = without_timings(run_explore([*DEMO_ARGS, "--quiet"], out))
    assert metrics.pop("exit_code") == 0, "the README demo did not succeed"
    return metrics


def case_digests(case: str, tmp: Path) -> dict[str, str]:
    out = tmp / case
    metrics = run_explore([*CASES[case], *TINY], out)
    results = without_timings({k: v for k, v in metrics.items() if k != "config"})
    return {
        "frames": frames_digest(out / "recordings"),
        "votes": votes_digest(out),
        "metrics": json_digest(results),
        "config": json_digest(metrics["config"]),
    }


# ---------------------------------------------------------------------- tests
def platform_pins(case: str | None = None) -> dict[str, dict[str, str]]:
    """This platform's pinned hashes; the test is skipped, naming the platform (and
    ``case``), where none are pinned (a run repeats bit for bit on one platform, not across
    CPU vendors; a case whose behaviour changed stays unpinned on a platform until someone
    re-pins it on such a machine)."""
    names = float_platforms()  # the most specific pinned name first (its CPU family)
    for here in names:
        if here in PINNED and (case is None or case in PINNED[here]):
            return PINNED[here]
    here = names[0]
    what = here if case is None or not any(n in PINNED for n in names) else f"{case} on {here}"
    pytest.skip(
        f"no pinned hashes for {what!r} (pinned: {', '.join(sorted(PINNED))}); pin them "
        "with `python tests/test_pinned_results.py` on such a machine"
    )


@pytest.mark.slow
@pytest.mark.parametrize("case", sorted(CASES))
def test_pinned_hashes(case: str, tmp_path: Path) -> None:
    pins = platform_pins(case)
    got = case_digests(case, tmp_path)
    want = {**pins[case], "config": PINNED_CONFIG[case]}
    changed = {k: (want[k], got[k]) for k in want if got[k] != want[k]}
    assert not changed, (
        f"{case} on {float_platforms()[0]!r}: {sorted(changed)} changed (pinned, now): {changed}; "
        "if intended, regenerate with `python tests/test_pinned_results.py` on every platform "
        "pinned and give the reason in the commit message"
    )


def test_pinned_table_covers_every_case() -> None:
    assert set(PINNED_CONFIG) == set(CASES)
    assert all(len(v) == 64 and int(v, 16) >= 0 for v in PINNED_CONFIG.values())
    assert set(PINNED["x86_64 GenuineIntel"]) == set(CASES)  # where this project runs now
    for platform, table in PINNED.items():
        assert set(table) <= set(CASES), platform
        for case, digests in table.items():
            assert set(digests) == {"frames", "votes", "metrics"}, (platform, case)
            assert all(len(v) == 64 and int(v, 16) >= 0 for v in digests.values()), case


def test_a_platform_without_pins_is_skipped_by_name(monkeypatch) -> None:
    intel_seed1 = PINNED["x86_64 GenuineIntel"]["seed1_not_held"]
    monkeypatch.setattr(sys.modules[__name__], "float_platforms", lambda: ("riscv64 Nobody",))
    with pytest.raises(pytest.skip.Exception, match="riscv64 Nobody"):
        platform_pins()
    # a CPU family pinned on its own is looked up first; another falls back to its vendor's
    fine = {"x86_64 AuthenticAMD family 26": {"seed2_push": {}}, "x86_64 AuthenticAMD": {}}
    monkeypatch.setattr(sys.modules[__name__], "PINNED", fine)
    for family, want in (
        ("26", fine["x86_64 AuthenticAMD family 26"]),
        ("25", fine["x86_64 AuthenticAMD"]),
    ):
        names = (f"x86_64 AuthenticAMD family {family}", "x86_64 AuthenticAMD")
        monkeypatch.setattr(sys.modules[__name__], "float_platforms", lambda n=names: n)
        assert platform_pins() is want
    # a platform pinned for some cases skips the others by name
    table = {"x86_64 GenuineIntel": {"seed1_not_held": intel_seed1}}
    monkeypatch.setattr(sys.modules[__name__], "PINNED", table)
    monkeypatch.setattr(
        sys.modules[__name__],
        "float_platforms",
        lambda: ("x86_64 GenuineIntel family 6", "x86_64 GenuineIntel"),
    )
    for unpinned in ("seed2_push", "seed3_sampler"):
        with pytest.raises(
            pytest.skip.Exception, match=f"{unpinned} on x86_64 GenuineIntel family 6"
        ):
            platform_pins(unpinned)
    assert platform_pins("seed1_not_held") is table["x86_64 GenuineIntel"]


def test_platform_names_run_from_the_cpu_family_to_the_vendor() -> None:
    names = float_platforms()
    assert names[-1] == float_platform() and len(names) in (1, 2)
    if len(names) == 2:  # /proc/cpuinfo names the family
        assert re.fullmatch(re.escape(float_platform()) + r" family \d+", names[0]), names


def test_timings_are_removed_at_any_depth() -> None:
    doc = {"a": 1, "timings_s": {"x": 1.0}, "l": [{"timings_s": 2, "b": [3]}]}
    assert without_timings(doc) == {"a": 1, "l": [{"b": [3]}]}
    assert json_digest({"b": 1, "a": 2}) == json_digest({"a": 2, "b": 1})
    assert json_digest({"a": 1.0}) != json_digest({"a": 1.0000000000000002})


@pytest.mark.skipif(
    not os.environ.get("CABLESIM_PIN_DEMO"),
    reason="the README demo takes minutes: set CABLESIM_PIN_DEMO=1 to compare its metrics",
)
def test_readme_demo_metrics_unchanged(tmp_path: Path) -> None:
    if float_platform() != DEMO_PLATFORM:
        pytest.skip(f"the demo's metrics are pinned on {DEMO_PLATFORM!r}, not {float_platform()!r}")
    want = json.loads(DEMO_METRICS.read_text())
    got = demo_metrics(tmp_path / "demo")
    # compared as canonical JSON text: NaN (a score of an empty mask) equals NaN there
    changed = sorted(
        k for k in set(got) | set(want) if json_digest(got.get(k)) != json_digest(want.get(k))
    )
    assert not changed, f"the README demo's metrics changed in {changed}"


# ---------------------------------------------------------------------- regenerating
def _print_pinned() -> None:
    with tempfile.TemporaryDirectory() as tmp:
        table = {case: case_digests(case, Path(tmp)) for case in sorted(CASES)}
    print("# PINNED's entry for this platform, then PINNED_CONFIG")
    print(f'    "{float_platforms()[0]}": {{')
    for case, digests in table.items():
        print(f'        "{case}": {{')
        for k in ("frames", "votes", "metrics"):
            print(f'            "{k}": "{digests[k]}",')
        print("        },")
    print("    },")
    print("PINNED_CONFIG: dict[str, str] = {")
    for case, digests in table.items():
        print(f'    "{case}": "{digests["config"]}",')
    print("}")


def _write_demo() -> None:
    with tempfile.TemporaryDirectory() as tmp:
        metrics = demo_metrics(Path(tmp) / "demo")
    DEMO_METRICS.parent.mkdir(parents=True, exist_ok=True)
    DEMO_METRICS.write_text(json.dumps(metrics, indent=2) + "\n")
    print(f"wrote {DEMO_METRICS} on {float_platform()!r} (DEMO_PLATFORM must name it)")


if __name__ == "__main__":
    _write_demo() if sys.argv[1:] == ["--demo"] else _print_pinned()
