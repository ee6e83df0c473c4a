"""Receivers: one set of arrivals and a late envelope rendered into an RIR. An omni capsule
(:mod:`.synthesis`: fractional-delay taps and band-shaped noise, which the others build on),
microphone arrays and ambisonics (:mod:`.arrays`), and binaural ears (:mod:`.hrtf`: the
rigid-sphere head or a measured HRIR set)."""
