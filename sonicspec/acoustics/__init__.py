"""The acoustics library: room impulse responses from a scene, and paths that move.

Arrays and small settings objects in, arrays and small result objects out: nothing here reads
the spec, the store or a file the caller did not name (DESIGN.md §2). The pipeline of one RIR,
as :func:`~sonicspec.acoustics.engine.simulate_rirs` runs it for one microphone and many
source positions, with the subpackage that does each step::

    mesh + materials (sonicspec.geometry)
      │  engine.acoustic_scene: absorption, scattering, transmission per face and band
      ▼
    room/       scene: the mesh on Embree (first hits, occlusion, crossings)
      │         simplify: flat areas re-triangulated (same surfaces, creases, materials)
      ├─────────────────────────────────┐
      ▼ exact, per source position      ▼ stochastic, one trace from the microphone
    paths/      direct sound          late/   raytrace: every source position a receiver
                image_sources (ISM)           (reciprocity), diffuse rain
                edges → edge_paths            → per-band energy histograms
                (UTD, diffraction)            tails: where each band's decay ends, the
      │         → Arrivals: delay,            rays' last 20 dB carried on
      │           directions, amplitude       → the late envelope
      │           per band                    │
      ├─────────────────────────────────┬─────┘
      ▼                                 ▼
    moving/     delays: the exact    receivers/  synthesis: fractional-delay taps and
                paths as time-varying            band-shaped noise (mono)
                delays while a source            arrays: capsule delays; ambisonics
                or the microphone                hrtf: sphere head, SOFA HRIRs (binaural)
                moves (Doppler; the              capsules: first-order patterns
                render stage's                   devices: presets (arrays, em32)
                ``interpolation: paths``)        → RIR (channels, samples)
                                                 → metrics: T30, EDT, C50, DRR

Shared basics at the top: :mod:`.bands` (octave bands, a filter bank that sums to one),
:mod:`.air` (ISO 9613-1), :mod:`.arrivals` (the result types every step hands on),
:mod:`.directions` (sphere lattices), :mod:`.directivity` (source and capsule patterns per
band, where a talker faces), :mod:`.metrics` (ISO 3382-1 figures) and
:mod:`.engine` (runs the steps above; the one module that reads the geometry library's types).

**References**: :mod:`sonicspec.acoustics.theory` holds the exact answers the engine is
measured against (Sabine, Eyring, Kuttruff; Barron; the exact moving point source and moving
image sources; the exact wedge diffraction of Svensson and Keller's geometric theory). It
imports nothing of the engine; ``moving/`` uses its retarded-time solution and sinc.

Imports go down this picture only: the basics import no subpackage; ``room`` stands on the
basics; ``paths`` on ``room``; ``late`` on ``paths`` and ``room``; ``receivers`` on the basics;
``moving`` on ``receivers``; ``engine`` on all (tests/test_layers.py checks it).
"""
