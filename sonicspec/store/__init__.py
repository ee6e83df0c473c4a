"""Content-hashed Zarr artifact store (DESIGN.md §3)."""

from sonicspec.store.artifacts import Artifact, ArtifactStore, VerifyProblem, array_digest

__all__ = ["Artifact", "ArtifactStore", "VerifyProblem", "array_digest"]
