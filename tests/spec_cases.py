"""A valid base spec with known line numbers, and one-line edits that break it.

Each case: (id, old text, new text, expected field path, expected line, JSON Schema rejects?).
The last flag is True for type-level errors (the schema and pydantic must both reject) and
False for semantic errors that only ``sonicspec validate`` can see (the schema accepts).
"""

BASE = """\
sonicspec: 1
name: base
seed: 1
sample_rate_hz: 16000
scenes:
  - kind: shoebox
    id: room
    size_m: [6, 5, 3]
    materials: {walls: plaster_on_brick, floor: parquet_on_concrete, ceiling: plaster_on_concrete}
    obstacles:
      - {kind: box, center_m: [2, 2, 0.5], size_m: [1, 1, 1], material: wood_panel}
  - kind: l_shape
    id: ell
    size_m: [8, 6, 3]
    cutout_m: [3, 2]
materials:
  library: sonicspec
  custom:
    foam: {absorption: 0.8}
microphone:
  kind: circular_array
  n: 4
  radius_m: 0.05
placement:
  source_start_distance_m: [1, 4]
  wall_clearance_m: 0.3
trajectory:
  kind: shortest_path
  rir_spacing_m: 0.25
acoustics:
  rays: 5000
  image_source_order: 2
corpora:
  speech: {kind: librispeech, root: data/ls, subsets: {train: [train-clean-100], test: [test-clean]}}
  noise: {kind: fsd50k, root: data/fsd, split_ratios: {train: 0.8, test: 0.2}}
mixture:
  duration_s: 20
  speakers: 2
  utterances_per_speaker: [1, 3]
  loudness: {speech_lufs: -17}
  tasks:
    - {kind: separation, speakers: 2, background: noise}
splits:
  train: {groups: 4, scenes: [room]}
  test: {groups: 2, scenes: [ell]}
outputs:
  audio_format: flac
  subtype: PCM_16
"""

SPEECH = ("speech: {kind: librispeech, root: data/ls, "
          "subsets: {train: [train-clean-100], test: [test-clean]}}")

CASES = [
    # --- type-level: pydantic and JSON Schema both reject ------------------------------------
    ("name-pattern", "name: base", 'name: "my data"', "name", 2, True),
    ("seed-negative", "seed: 1", "seed: -1", "seed", 3, True),
    ("rate-too-low", "sample_rate_hz: 16000", "sample_rate_hz: 4000", "sample_rate_hz", 4, True),
    ("size-negative", "size_m: [6, 5, 3]", "size_m: [6, -5, 3]", "scenes[0].size_m", 8, True),
    ("size-two-values", "size_m: [6, 5, 3]", "size_m: [6, 5]", "scenes[0].size_m", 8, True),
    ("scene-kind", "  - kind: shoebox", "  - kind: shoebx", "scenes[0].kind", 6, True),
    ("scene-extra-key", "    id: room", "    id: room\n    colour: red", "scenes[0].colour", 8,
     True),
    ("top-level-typo", "seed: 1", "sed: 1", "sed", 3, True),
    ("obstacle-kind", "{kind: box,", "{kind: sphere,", "scenes[0].obstacles[0].kind", 11, True),
    ("obstacle-size", "size_m: [1, 1, 1]", "size_m: [1, 0, 1]", "scenes[0].obstacles[0].size_m",
     11, True),
    # Bounded inputs (issue 16): sizes a tracer and a walkable-area grid can hold, ray and
    # group counts a build can finish.
    ("size-huge", "size_m: [6, 5, 3]", "size_m: [1e9, 5, 3]", "scenes[0].size_m", 8, True),
    ("obstacle-size-huge", "size_m: [1, 1, 1]", "size_m: [1, 1, 2000]",
     "scenes[0].obstacles[0].size_m", 11, True),
    ("obstacle-far", "center_m: [2, 2, 0.5]", "center_m: [2, 2e6, 0.5]",
     "scenes[0].obstacles[0].center_m", 11, True),
    ("cutout-huge", "cutout_m: [3, 2]", "cutout_m: [3, 1001]", "scenes[1].cutout_m", 15, True),
    ("rays-too-many", "rays: 5000", "rays: 10000000", "acoustics.rays", 31, True),
    ("groups-too-many", "train: {groups: 4,", "train: {groups: 1000001,", "splits.train.groups",
     44, True),
    ("cutout-three-values", "cutout_m: [3, 2]", "cutout_m: [3, 2, 1]", "scenes[1].cutout_m", 15,
     True),
    ("library-typo", "library: sonicspec", "library: sonicsett", "materials.library", 17, True),
    ("absorption-above-one", "foam: {absorption: 0.8}", "foam: {absorption: 1.5}",
     "materials.custom.foam.absorption", 19, True),
    ("absorption-band-count", "foam: {absorption: 0.8}",
     "foam: {absorption: [0.1, 0.2, 0.3, 0.4, 0.5]}", "materials.custom.foam.absorption", 19, True),
    ("scattering-override-above-one", "library: sonicspec",
     "library: sonicspec\n  scattering_override: 1.5", "materials.scattering_override", 18, True),
    ("scattering-override-band-count", "library: sonicspec",
     "library: sonicspec\n  scattering_override: [1, 1]", "materials.scattering_override", 18,
     True),
    ("mic-kind", "kind: circular_array", "kind: circular", "microphone.kind", 21, True),
    ("mic-one-capsule", "  n: 4", "  n: 1", "microphone.n", 22, True),
    ("mic-radius-zero", "radius_m: 0.05", "radius_m: 0", "microphone.radius_m", 23, True),
    ("mic-capsule-pattern", "radius_m: 0.05", "radius_m: 0.05\n  capsule: {pattern: shotgun}",
     "microphone.capsule.pattern", 24, True),
    ("mic-capsule-axis-and-azimuth", "radius_m: 0.05", "radius_m: 0.05\n  capsule: {pattern: "
     "cardioid, axis: [1, 0, 0], azimuth_deg: 30}", "microphone.capsule", 24, False),
    ("mic-device-unknown", "kind: circular_array\n  n: 4\n  radius_m: 0.05",
     "kind: device\n  device: echo_dot", "microphone.device", 22, True),
    ("mic-line-open", "radius_m: 0.05", "radius_m: 0.05\n  trajectory: {kind: line, start_m: [1, 1, "
     "1.5]}", "microphone.trajectory.end_m", 24, True),
    ("mic-shortest-path", "radius_m: 0.05", "radius_m: 0.05\n  trajectory: {kind: shortest_path}",
     "microphone.trajectory.kind", 24, True),
    ("mic-moving-and-placed", "kind: circular_array\n  n: 4\n  radius_m: 0.05\nplacement:",
     "kind: mono\n  trajectory: {kind: line, start_m: [1, 1, 1.5], end_m: [2, 1, 1.5]}\n"
     "placement:\n  mic_position_m: [3, 3, 1.5]", "placement.mic_position_m", 24, False),
    ("range-negative", "source_start_distance_m: [1, 4]", "source_start_distance_m: [-1, 4]",
     "placement.source_start_distance_m", 25, True),
    ("clearance-negative", "wall_clearance_m: 0.3", "wall_clearance_m: -0.3",
     "placement.wall_clearance_m", 26, True),
    ("trajectory-kind", "kind: shortest_path", "kind: shortest", "trajectory.kind", 28, True),
    ("rir-spacing-zero", "rir_spacing_m: 0.25", "rir_spacing_m: 0", "trajectory.rir_spacing_m", 29,
     True),
    ("rays-too-few", "rays: 5000", "rays: 10", "acoustics.rays", 31, True),
    ("ism-order-too-high", "image_source_order: 2", "image_source_order: 20",
     "acoustics.image_source_order", 32, True),
    ("bands-unknown", "image_source_order: 2", "image_source_order: 2\n  bands_hz: [100, 250]",
     "acoustics.bands_hz[0]", 33, True),
    ("temperature-too-high", "image_source_order: 2", "image_source_order: 2\n  temperature_c: 90",
     "acoustics.temperature_c", 33, True),
    # max_rir_length_s: seconds or 'auto' (issue 19); the cap is seconds.
    ("rir-length-word", "image_source_order: 2",
     "image_source_order: 2\n  max_rir_length_s: longest", "acoustics.max_rir_length_s", 33, True),
    ("rir-length-zero", "image_source_order: 2", "image_source_order: 2\n  max_rir_length_s: 0",
     "acoustics.max_rir_length_s", 33, True),
    ("rir-cap-too-long", "image_source_order: 2",
     "image_source_order: 2\n  max_rir_cap_s: 120", "acoustics.max_rir_cap_s", 33, True),
    ("corpus-kind", "{kind: librispeech,", "{kind: librispeach,", "corpora.speech.kind", 34, True),
    ("corpus-root-missing", "root: data/ls, ", "", "corpora.speech.root", 34, True),
    ("duration-negative", "duration_s: 20", "duration_s: -20", "mixture.duration_s", 37, True),
    ("speakers-zero", "speakers: 2\n  utt", "speakers: 0\n  utt", "mixture.speakers", 38, True),
    ("utterances-zero", "utterances_per_speaker: [1, 3]", "utterances_per_speaker: [0, 3]",
     "mixture.utterances_per_speaker", 39, True),
    ("utterances-fraction", "utterances_per_speaker: [1, 3]", "utterances_per_speaker: [1.5, 3]",
     "mixture.utterances_per_speaker[0]", 39, True),
    ("loudness-positive", "speech_lufs: -17", "speech_lufs: 5", "mixture.loudness.speech_lufs", 40,
     True),
    ("floor-area-huge", "size_m: [6, 5, 3]", "size_m: [200, 100, 3]", "scenes[0]", 6, False),
    ("groups-total-too-many", "train: {groups: 4,", "train: {groups: 999999,", "splits", 44,
     False),
    ("loudness-preset-clash", "speech_lufs: -17", "preset: sonicset_release, speech_lufs: -20",
     "mixture.loudness", 40, False),
    ("task-kind", "{kind: separation,", "{kind: seperation,", "mixture.tasks[0].kind", 42, True),
    ("task-background", "background: noise}", "background: nois}", "mixture.tasks[0].background",
     42, True),
    ("groups-zero", "train: {groups: 4,", "train: {groups: 0,", "splits.train.groups", 44, True),
    ("split-scenes-missing", "train: {groups: 4, scenes: [room]}", "train: {groups: 4}",
     "splits.train.scenes", 44, True),
    ("split-name", "  train: {groups: 4", '  "1train": {groups: 4', 'splits["1train"]', 44, True),
    ("audio-format", "audio_format: flac", "audio_format: mp3", "outputs.audio_format", 47, True),
    ("subtype", "subtype: PCM_16", "subtype: PCM_8", "outputs.subtype", 48, True),
    ("version-missing", "sonicspec: 1\n", "", "sonicspec", 1, True),
    ("version-newer", "sonicspec: 1", "sonicspec: 2", "sonicspec", 1, True),
    ("version-text", "sonicspec: 1", "sonicspec: one", "sonicspec", 1, True),
    ("scenes-empty-list", "scenes:\n  - kind: shoebox\n    id: room",
     "scenes: []\nunused:\n  - kind: shoebox\n    id: room", "scenes", 5, True),
    # --- semantic: only sonicspec validate sees them; the schema accepts ----------------------
    ("range-reversed", "source_start_distance_m: [1, 4]", "source_start_distance_m: [4, 1]",
     "placement.source_start_distance_m", 25, False),
    ("scene-id-duplicate", "id: ell", "id: room", "scenes[1].id", 13, False),
    ("material-unknown", "walls: plaster_on_brick", "walls: plaster_on_brik",
     "scenes[0].materials.walls", 9, False),
    ("obstacle-material-unknown", "material: wood_panel}", "material: wood_panell}",
     "scenes[0].obstacles[0].material", 11, False),
    ("cutout-too-big", "cutout_m: [3, 2]", "cutout_m: [9, 2]", "scenes[1].cutout_m", 15, False),
    ("box-outside-room", "center_m: [2, 2, 0.5]", "center_m: [5.8, 2, 0.5]",
     "scenes[0].obstacles[0].center_m", 11, False),
    ("split-unknown-scene", "scenes: [room]}", "scenes: [rooom]}", "splits.train.scenes[0]", 44,
     False),
    ("splits-share-scene", "scenes: [ell]}", "scenes: [ell, room]}", "splits.test.scenes", 45,
     False),
    ("subset-missing-for-split", "test: [test-clean]}}", "val: [test-clean]}}",
     "corpora.speech.subsets", 34, False),
    ("ratios-sum", "{train: 0.8, test: 0.2}", "{train: 0.8, test: 0.3}",
     "corpora.noise.split_ratios", 35, False),
    ("task-more-speakers", "{kind: separation, speakers: 2,", "{kind: separation, speakers: 3,",
     "mixture.tasks[0].speakers", 42, False),
    ("task-music-without-corpus", "background: noise}", "background: music}",
     "mixture.tasks[0].background", 42, False),
    ("flac-float", "subtype: PCM_16", "subtype: FLOAT", "outputs.subtype", 48, False),
    ("bits-without-scale", "subtype: PCM_16", "subtype: PCM_16\n  bits: 16", "outputs.bits",
     49, False),
    ("bits-beyond-pcm16", "subtype: PCM_16", "subtype: PCM_16\n  scale: per_file\n  bits: 20",
     "outputs.bits", 50, False),
    ("bits-below-16", "subtype: PCM_16", "subtype: PCM_24\n  scale: per_file\n  bits: 12",
     "outputs.bits", 50, True),
    ("scale-name", "subtype: PCM_16", "subtype: PCM_16\n  scale: peak", "outputs.scale", 49,
     True),
    ("levels-kept-in-pcm", "loudness: {speech_lufs: -17}",
     "loudness: {speech_lufs: -17, peak_limit_dbfs: null}",
     "mixture.loudness.peak_limit_dbfs", 40, False),
    ("diffraction-edge-budget", "image_source_order: 2",
     "image_source_order: 2\n  diffraction_max_edges: -1", "acoustics.diffraction_max_edges",
     33, True),
    # issue 28 item 11: a clip no utterance fits after the longest gap (the build failed 39 s in)
    ("clip-shorter-than-gap", "duration_s: 20", "duration_s: 6", "mixture.utterance_gap_s", 37,
     False),
    ("band-above-nyquist", "sample_rate_hz: 16000", "sample_rate_hz: 16000",
     "acoustics.bands_hz[1]", 33, False),
    ("mic-above-ceiling", "radius_m: 0.05", "radius_m: 0.05\n  height_m: 3.5",
     "microphone.height_m", 24, False),
    ("distance-beyond-room", "source_start_distance_m: [1, 4]",
     "source_start_distance_m: [20, 30]", "placement.source_start_distance_m", 25, False),
]

# The band-above-Nyquist case needs a second edit; kept here so CASES stays one-line edits.
EXTRA_EDITS = {
    "band-above-nyquist": ("image_source_order: 2", "image_source_order: 2\n  bands_hz: [125, 8000]"),
}


def apply(case: tuple) -> str:
    """The base spec with the case's edit (exactly one occurrence is replaced)."""
    cid, old, new = case[0], case[1], case[2]
    assert BASE.count(old) >= 1, f"{cid}: {old!r} not in the base spec"
    text = BASE.replace(old, new, 1)
    if cid in EXTRA_EDITS:
        a, b = EXTRA_EDITS[cid]
        text = text.replace(a, b, 1)
    return text
