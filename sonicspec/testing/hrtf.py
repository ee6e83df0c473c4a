"""A tiny SOFA HRIR set whose every direction can be recognised in a rendered output."""

from __future__ import annotations

import numpy as np


def write_tiny_sofa(path: str, sample_rate_hz: float) -> None:
    """Four directions (front, left, back, right), SimpleFreeFieldHRIR.

    Direction ``m`` has a unit impulse at tap ``2 + m`` in the left ear and 0.5 at tap
    ``10 + 2m`` in the right, so the measurement chosen for an arrival can be read off.
    """
    import sofar

    sofa = sofar.Sofa("SimpleFreeFieldHRIR")
    sofa.SourcePosition = np.array([[0, 0, 1.0], [90, 0, 1.0], [180, 0, 1.0], [270, 0, 1.0]])
    ir = np.zeros((4, 2, 32))
    for m in range(4):
        ir[m, 0, 2 + m] = 1.0
        ir[m, 1, 10 + 2 * m] = 0.5
    sofa.Data_IR = ir
    sofa.Data_SamplingRate = sample_rate_hz
    sofar.write_sofa(path, sofa)
