"""Fuzzing configs: any edit of a config's JSON either gives a config that validates and lays
out a finite scene (one that MuJoCo compiles and steps), or a ConfigError naming a field."""

from __future__ import annotations

import copy
import math
from typing import Any

import mujoco
import numpy as np
from hypothesis import given
from hypothesis import strategies as st

from cablesim.config import from_dict, to_dict
from cablesim.dataset.randomize import Randomization
from cablesim.envs.hose_explore import HoseExploreConfig
from cablesim.episode.config import InteractionConfig
from cablesim.errors import ConfigError
from cablesim.policies.config import ExploreConfig
from cablesim.sim.config import EpisodeConfig, PerturbConfig, SceneConfig
from cablesim.sim.layout import sample_camera, sample_hoses, start_shape
from cablesim.sim.world import World, _scene_xml, look_at_frame
from cablesim.thesis.config import ThesisConfig

from ._fuzz import HOSTILE, fuzz, own_error_or_result

CLASSES = (
    SceneConfig,
    EpisodeConfig,
    InteractionConfig,
    PerturbConfig,
    ExploreConfig,
    HoseExploreConfig,
    ThesisConfig,
    Randomization,
)


def leaves(doc: Any, path: tuple = ()) -> list[tuple]:
    """Paths (keys and list indices) of every value inside ``doc``, containers included."""
    items = doc.items() if isinstance(doc, dict) else enumerate(doc)
    out = []
    for k, v in items:
        out.append((*path, k))
        if isinstance(v, list | dict):
            out += leaves(v, (*path, k))
    return out


def get(doc: Any, path: tuple) -> Any:
    for k in path:
        doc = doc[k]
    return doc


def put(doc: Any, path: tuple, value: Any) -> None:
    get(doc, path[:-1])[path[-1]] = value


@st.composite
def edited(draw: st.DrawFn, cls: type, plausible: bool) -> dict:
    """The JSON of a default ``cls`` with one to three leaves replaced: by hostile values, or
    (``plausible``) numbers scaled, shifted or negated."""
    doc = to_dict(cls())
    for _ in range(draw(st.integers(1, 3))):
        paths = leaves(doc)
        if not paths:
            break
        path = draw(st.sampled_from(paths))
        old = get(doc, path)
        if plausible and isinstance(old, int | float) and not isinstance(old, bool):
            scale = draw(st.sampled_from([0.0, 0.5, 2.0, 10.0, 100.0, -1.0, 1e-6]))
            new = old * scale + draw(st.sampled_from([0, 0, 1, -1]))
            new = int(new) if isinstance(old, int) else float(new)
        else:
            new = draw(HOSTILE)
        put(doc, path, new)
    return doc


@fuzz(150)
@given(st.sampled_from(CLASSES).flatmap(lambda c: st.tuples(st.just(c), edited(c, False))))
def test_hostile_values_are_named(case):
    cls, doc = case
    cfg = own_error_or_result(from_dict, cls, copy.deepcopy(doc))
    if cfg is not None:  # it was checked when it was made: it prints and rebuilds as it is
        assert from_dict(cls, to_dict(cfg)) == cfg


def check_layout(cfg: SceneConfig) -> None:
    """The pure-NumPy part of building: finite hose shapes and a camera frame."""
    specs = sample_hoses(cfg)
    assert len(specs) == cfg.hoses.count
    for s in specs:
        assert math.isfinite(s.length) and s.n_vertices >= 8
        assert np.all(np.isfinite(start_shape(cfg, s)))
    cam = sample_camera(cfg)
    R = look_at_frame(cam.position, cam.look_at)
    assert np.all(np.isfinite(R)) and np.allclose(R.T @ R, np.eye(3), atol=1e-9)


@fuzz(60)
@given(edited(SceneConfig, True))
def test_plausible_scene_edits_lay_out_or_are_named(doc):
    cfg = own_error_or_result(SceneConfig.from_dict, doc)
    if cfg is None:
        return
    check_layout(cfg)


@fuzz(8, deadline_ms=None)
@given(edited(SceneConfig, True))
def test_valid_scenes_compile_and_step(doc):
    """MuJoCo never sees a degenerate model: a config that exists compiles (without the
    arm, to stay fast) and takes a few steps, or fails with the project's own error."""
    if isinstance(doc.get("robot"), dict):
        doc["robot"]["enabled"] = False
    cfg = own_error_or_result(SceneConfig.from_dict, doc)
    if cfg is None:
        return
    check_layout(cfg)
    world = own_error_or_result(World.build, cfg, settle=False)
    if world is not None:
        own_error_or_result(world.step, 25)
        assert isinstance(world.model, mujoco.MjModel)


def test_the_xml_of_a_valid_scene_has_no_nan():
    cfg = SceneConfig(seed=3)
    xml = _scene_xml(cfg, sample_hoses(cfg), sample_camera(cfg))
    assert "nan" not in xml.lower() and "inf" not in xml.replace("info", "").lower()


def test_validate_names_a_field():
    try:
        SceneConfig.from_dict({"camera": {"fovy": float("nan")}})
    except ConfigError as e:
        assert e.field == "camera.fovy"
    else:  # pragma: no cover
        raise AssertionError("a NaN field of view was accepted")
