"""The stochastic late field: rays traced from the microphone with diffuse rain into per-band
energy histograms (:mod:`.raytrace`, compiled per-hit work in :mod:`._trace_kernels`), and
where each band's tail ends and how it is carried on past the rays (:mod:`.tails`)."""
