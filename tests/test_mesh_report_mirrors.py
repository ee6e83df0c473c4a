"""The mesh artifact's typed report (sonicspec.artifacts.mesh_report) mirrors what the geometry
library's reports dump (``to_dict()``) key by key: a field added to one and not the other fails
here, not in a stored artifact."""

from __future__ import annotations

import dataclasses

import pytest

from sonicspec.artifacts import mesh_report as mr
from sonicspec.geometry import repair


@pytest.mark.parametrize(("facts", "report"), [
    (mr.RepairFacts, repair.RepairReport),
    (mr.MeshStatsFacts, repair.MeshStats),
    (mr.WeldFacts, repair.WeldReport),
])
def test_the_typed_report_has_the_library_report_s_keys(facts, report) -> None:
    library = {f.name for f in dataclasses.fields(report)}
    # the derived keys to_dict() adds (watertight) are fields of the typed record
    derived = {"watertight"} if report is not repair.WeldReport else set()
    assert set(facts.model_fields) - {"leak"} == (library | derived) - {"leak"}
