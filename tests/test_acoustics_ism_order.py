"""The image-source order a RIR reached, and why it is lower than asked (issue 27, item 6).

A room whose vertices are jittered by ±2 mm, as real scans are, has no flat regions: every
triangle is a mirror of its own. Beam pruning lets its search reach order 3; where the
candidate cap still stops it below the asked order, that must be said per RIR, per source in
the rir artifact, and in a warning line of the job's log naming the scene (which the build
summary collects).
"""

from __future__ import annotations

import logging
from types import SimpleNamespace

import numpy as np
import pytest

import sonicspec as ss
from sonicspec.errors import SonicspecWarning
from sonicspec.geometry.mesh import SceneMesh
from sonicspec.geometry.procedural import shoebox
from sonicspec.stages import rir as rir_stage

SOURCE, MIC = [1.5, 1.2, 1.4], [4.2, 3.1, 1.6]
SETTINGS = ss.RirSettings(rays=300, image_source_order=3, simplify_tolerance_m=0,
                          max_rir_length_s=0.3)


def subdivided_room(jitter_m: float) -> ss.Scene:
    """A 6 x 5 x 3 m shoebox cut into 160 triangles, vertices jittered by ``jitter_m``."""
    import trimesh.remesh

    room = shoebox([6.0, 5.0, 3.0])
    v, f = trimesh.remesh.subdivide_to_size(room.vertices, room.faces, max_edge=2.0)
    v = v + np.random.default_rng(0).uniform(-jitter_m, jitter_m, v.shape)
    return ss.Scene.from_mesh(SceneMesh(v, f, np.zeros(len(f), np.int32),
                                        ("plaster_on_brick",)))


def test_a_jittered_scan_reports_the_order_it_reached(monkeypatch) -> None:
    from sonicspec.acoustics.paths import image_sources as ism

    # pruned, the jittered room's order 3 fits under the cap (it did not before: issue 27)
    reached = ss.compute_rir(subdivided_room(0.002), SOURCE, MIC, SETTINGS, seed=0)
    assert (reached.image_source_order, reached.image_source_order_stopped) == (3, None)
    # a cap it does not fit under: the order reached and why are reported
    monkeypatch.setattr(ism, "MAX_CANDIDATES", 5000)
    with pytest.warns(SonicspecWarning, match="order 3 needs more than 5000 candidates"):
        cut = ss.compute_rir(subdivided_room(0.002), SOURCE, MIC, SETTINGS, seed=0)
    assert (cut.image_source_order, cut.image_source_order_asked) == (2, 3)
    assert cut.image_source_order_stopped == "order 3 needs more than 5,000 candidates"
    facts = cut.to_dict()
    assert facts["image_source_order_asked"] == 3
    assert facts["image_source_order_stopped"] == cut.image_source_order_stopped
    # the same room without the jitter: its walls are six flat mirrors, order 3 is reached
    clean = ss.compute_rir(subdivided_room(0.0), SOURCE, MIC, SETTINGS, seed=0)
    assert (clean.image_source_order, clean.image_source_order_stopped) == (3, None)


def test_the_rir_job_says_which_scene_and_group_got_a_lower_order(caplog) -> None:
    # the fields of the engine's RirFacts the step reads
    facts = [SimpleNamespace(image_source_order=3, image_source_order_stopped=None),
             SimpleNamespace(image_source_order=2, image_source_order_stopped=(
                 "order 3 needs more than 2,000,000 candidates"))]
    assert rir_stage._order_reached(facts, 3) == {
        "image_source_order": 2, "image_source_order_asked": 3,
        "image_source_order_stopped": "order 3 needs more than 2,000,000 candidates"}
    with caplog.at_level(logging.WARNING, logger=rir_stage.log.name):
        rir_stage._warn_lower_order("scene 'flat'", "g000001", 3, facts)
        rir_stage._warn_lower_order("scene 'flat'", "g000002", 3, facts[:1])  # reached: silent
    (record,) = caplog.records
    assert record.levelname == "WARNING"
    assert record.getMessage().startswith(
        "scene 'flat', group g000001: image-source order 3 asked, 2 reached in 1 of 2 RIRs "
        "(order 3 needs more than 2,000,000 candidates)")
