"""Parallel jobs (cablesim.jobs): local processes and a local Ray instance give the same result
files, runs resume, failures are named outcomes, bad job lists are refused up front."""

from __future__ import annotations

import json
import time
from pathlib import Path

import pytest

from cablesim.errors import ConfigError
from cablesim.jobs import Job, execute, load_results, parse_range, read_result


def _echo_jobs() -> list[Job]:
    return [
        Job("test.echo", "a", {"value": 1}),
        Job("test.echo", "b", {"value": [1, 2.5, "x"]}),
        Job("test.echo", "c", {"fail": "no_start_segment"}),
        Job("test.echo", "d", {"raise": "boom"}),
    ]


def _files(d: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in sorted(d.glob("*.json"))}


def test_local_pool_and_in_process_write_the_same_files(tmp_path):
    s1 = execute(_echo_jobs(), tmp_path / "one", workers=1, progress=False)
    s2 = execute(_echo_jobs(), tmp_path / "two", workers=2, progress=False)
    assert _files(tmp_path / "one") == _files(tmp_path / "two")
    assert len(_files(tmp_path / "one")) == 4
    for s in (s1, s2):
        assert (s.total, s.ran, s.skipped, s.ok) == (4, 4, 0, 2)
        assert s.failures == {"no_start_segment": ["c"], "InputError": ["d"]}
        assert "failed [InputError]: d" in s.report()
    d = read_result(tmp_path / "one" / "d.json")
    assert d["status"] == "failed" and "asked to fail: boom" in d["result"]["error"]
    assert read_result(tmp_path / "one" / "b.json")["result"]["value"] == [1, 2.5, "x"]
    # timings live beside the results, one line per job run
    lines = (tmp_path / "one" / "timings.jsonl").read_text().splitlines()
    assert {json.loads(x)["key"] for x in lines} == {"a", "b", "c", "d"}


def test_resume_skips_finished_jobs_and_reruns_damaged_ones(tmp_path):
    dry = execute(_echo_jobs(), tmp_path, workers=1, progress=False, dry=True)
    assert (dry.ran, dry.missing, dry.ok, dry.failed) == (0, 4, 0, 0)
    assert "4 not run" in dry.report() and not list(tmp_path.glob("*.json"))
    execute(_echo_jobs(), tmp_path, workers=1, progress=False)
    before = (tmp_path / "a.json").stat().st_mtime_ns
    (tmp_path / "b.json").write_text("{not json")  # a file cut short by a crash
    s = execute(_echo_jobs(), tmp_path, workers=1, progress=False)
    assert (s.skipped, s.ran) == (3, 1)
    assert (tmp_path / "a.json").stat().st_mtime_ns == before
    assert read_result(tmp_path / "b.json")["status"] == "ok"
    s = execute(_echo_jobs(), tmp_path, workers=1, progress=False, retry_failed=True)
    assert s.ran == 2  # the two failed ones
    assert [r["key"] for r in load_results(tmp_path, _echo_jobs())] == ["a", "b", "c", "d"]


def test_bad_job_lists_are_refused(tmp_path):
    with pytest.raises(ConfigError, match="job.kind"):
        execute([Job("nope", "a")], tmp_path, progress=False)
    with pytest.raises(ConfigError, match="share the key"):
        execute([Job("test.echo", "a"), Job("test.echo", "a")], tmp_path, progress=False)
    with pytest.raises(ConfigError, match="job.key"):
        execute([Job("test.echo", "../a")], tmp_path, progress=False)
    with pytest.raises(ConfigError, match="workers"):
        execute(_echo_jobs(), tmp_path, workers=-1, progress=False)
    assert parse_range("3:7") == (3, 7)
    for bad in ("7:3", "x", "1:2:3", "-1:2"):
        with pytest.raises(ConfigError, match="--scenes"):
            parse_range(bad)


@pytest.mark.slow
def test_ray_gives_the_local_result_files(tmp_path):
    """Two tiny scene jobs of the thesis benchmark through a local Ray instance
    (``ray.init(num_cpus=2)``) write the files the in-process executor writes."""
    pytest.importorskip("ray")
    from cablesim.thesis import ThesisConfig
    from cablesim.thesis.config import SceneSize

    cfg = ThesisConfig(
        validation=(11, 12),
        test=(21, 22),
        flows=("oracle",),
        explore_flow="oracle",
        perturb=(True,),
        scene=SceneSize(width=160, height=120, hoses=2, periods=1),
    )
    jobs = cfg.interaction_jobs()
    # the streams are simulated once (local run) and replayed from the cache by Ray's workers
    jobs = [
        Job(j.kind, j.key, {**j.params, "stream_cache": str(tmp_path / "streams")}) for j in jobs
    ]
    assert len(jobs) == 2
    local = execute(jobs, tmp_path / "local", workers=1, progress=False)
    t0 = time.perf_counter()
    ray = execute(jobs, tmp_path / "ray", workers=2, ray="local", progress=False)
    print(f"ray: {time.perf_counter() - t0:.1f} s for 2 jobs (with ray.init)")
    assert local.total == ray.total == 2 and ray.backend == "ray (local)"
    assert _files(tmp_path / "local") == _files(tmp_path / "ray")
    recs = load_results(tmp_path / "ray", jobs)
    assert local.outcomes == ray.outcomes
    ok = [r for r in recs if r["status"] == "ok"]
    assert ok, f"both scenes failed: {[r['outcome'] for r in recs]}"
    counts = ok[0]["result"]["flows"]["oracle"]["counts"]["correlation"]["1"]
    assert counts["npos"] > 0 and len(counts["tp"]) == 50
