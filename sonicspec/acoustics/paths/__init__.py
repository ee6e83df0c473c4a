"""Exact early paths, per source position: the direct sound (:mod:`.direct`), specular
reflections by image sources (:mod:`.image_sources`), and sound diffracted over the mesh's
edges (:mod:`.edges` finds the wedges, :mod:`.edge_paths` the paths over them,
:mod:`.diffraction` the UTD coefficient). Each gives
:class:`~sonicspec.acoustics.arrivals.Arrivals`."""
