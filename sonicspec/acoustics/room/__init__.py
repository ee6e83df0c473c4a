"""The room as sound meets it: the mesh on Embree with per-face acoustic coefficients
(:mod:`.scene`, every ray and occlusion query of the engine) and flat areas re-triangulated
before tracing (:mod:`.simplify`), each with its compiled loops beside it."""
