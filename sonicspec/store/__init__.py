"""Content-hashed Zarr artifact store (DESIGN.md §3)."""

from sonicspec.store.artifacts import Artifact, ArtifactStore, VerifyProblem

__all__ = ["Artifact", "ArtifactStore", "VerifyProblem"]
