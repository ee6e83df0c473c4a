"""The spec's ``directivity`` section: defaults leave specs (and their keys) as they were,
bad combinations are named."""

from __future__ import annotations

from pathlib import Path

import pytest
from pydantic import ValidationError

from sonicspec.errors import CompileError
from sonicspec.plan.compile import compile_spec
from sonicspec.spec import load_spec
from sonicspec.spec.directivity import DirectivitySpec

ROOT = Path(__file__).resolve().parents[1]


def _spec(tmp: Path, extra: str = "") -> Path:
    path = tmp / "demo.yaml"
    path.write_text((ROOT / "specs" / "demo.yaml").read_text() + extra)
    return path


def test_omni_sources_leave_the_spec_and_every_key_as_before(tmp_path: Path) -> None:
    plain = compile_spec(load_spec(_spec(tmp_path)), cache=False)
    (tmp_path / "b").mkdir()
    explicit = compile_spec(load_spec(_spec(tmp_path / "b", "directivity:\n  speech: "
                                                          "{pattern: omni}\n")), cache=False)
    assert [j.key for j in plain.jobs] == [j.key for j in explicit.jobs]
    assert "directivity" not in load_spec(_spec(tmp_path)).spec.model_dump(mode="json")


def test_a_talker_pattern_keys_the_rir_step_only_from_there_on(tmp_path: Path) -> None:
    plain = compile_spec(load_spec(_spec(tmp_path)), cache=False)
    (tmp_path / "b").mkdir()
    talker = compile_spec(load_spec(_spec(tmp_path / "b", "directivity:\n  speech: "
                                                        "{pattern: speech}\n")), cache=False)
    changed = {a.step for a, b in zip(plain.jobs, talker.jobs, strict=True) if a.key != b.key}
    assert changed == {"rir", "render", "mix", "export", "dataset"}
    rir = next(j for j in talker.jobs if j.step == "rir")
    assert rir.params["directivity"]["speech"]["pattern"] == "speech"


def test_bad_directivity_is_named(tmp_path: Path) -> None:
    with pytest.raises(ValidationError, match="sofa_path: expected a SOFA file exactly when"):
        DirectivitySpec(pattern="sofa")
    with pytest.raises(ValidationError, match="sofa_path: expected a SOFA file exactly when"):
        DirectivitySpec(pattern="speech", sofa_path="talker.sofa")
    with pytest.raises(ValidationError, match="pattern"):
        DirectivitySpec(pattern="trumpet")
    spec = _spec(tmp_path, "directivity:\n  speech: {pattern: sofa, sofa_path: nope.sofa}\n")
    with pytest.raises(CompileError, match=r"directivity.speech.sofa_path: SOFA file .*nope"):
        compile_spec(load_spec(spec), cache=False)


def test_a_directional_source_with_a_moving_microphone_compiles(tmp_path: Path) -> None:
    """Once refused; now the rir step pairs the source's and the microphone's positions in
    time (it reads the arrangement) and faces the source at each pair's time."""
    spec = _spec(tmp_path, "directivity:\n  noise: {pattern: cardioid}\n")
    loaded = load_spec(spec)
    moving = loaded.spec.model_copy(update={"microphone": loaded.spec.microphone.model_copy(
        update={"trajectory": _moving_trajectory()})})
    plan = compile_spec(type(loaded)(**{**loaded.__dict__, "spec": moving}), cache=False)
    rir = next(j for j in plan.jobs if j.step == "rir")
    arrange = next(j for j in plan.jobs if j.step == "arrange" and j.label.endswith(
        rir.label.removeprefix("rir")))
    assert rir.params["directivity"]["noise"]["pattern"] == "cardioid"
    assert "walk" in rir.params and arrange.key in rir.inputs


HEAD_TURN = "directivity:\n  speech: {pattern: PATTERN, head_turn: {std_deg: 15}}\n"


@pytest.mark.parametrize("interpolation", ["sample_crossfade", "stft_crossfade",
                                           "segment_ola"])
def test_head_turns_without_the_paths_are_refused_by_name(tmp_path: Path,
                                                         interpolation: str) -> None:
    from sonicspec.spec import validate_text

    text = _with_interpolation((ROOT / "specs" / "demo.yaml").read_text()
                               + HEAD_TURN.replace("PATTERN", "speech"), interpolation)
    loaded, problems = validate_text(text, str(tmp_path / "s.yaml"), tmp_path)
    assert loaded is None
    (error,) = [p for p in problems if p.severity == "error"]
    assert error.path == ("directivity", "speech", "head_turn")
    message = error.format("s.yaml")
    assert "directivity.speech.head_turn" in message and "mixture.interpolation" in message
    assert f"got {interpolation!r}" in message


@pytest.mark.parametrize("interpolation", ["paths", "auto"])
def test_head_turns_along_the_paths_validate(tmp_path: Path, interpolation: str) -> None:
    from sonicspec.spec import validate_text

    text = _with_interpolation((ROOT / "specs" / "demo.yaml").read_text()
                               + HEAD_TURN.replace("PATTERN", "speech"), interpolation)
    loaded, problems = validate_text(text, str(tmp_path / "s.yaml"), tmp_path)
    assert loaded is not None, [p.format("s.yaml") for p in problems]
    assert not [p for p in problems if p.path[:1] == ("directivity",)]


def test_head_turns_of_an_omni_source_are_a_warning(tmp_path: Path) -> None:
    from sonicspec.spec import validate_text

    text = _with_interpolation((ROOT / "specs" / "demo.yaml").read_text()
                               + HEAD_TURN.replace("PATTERN", "omni"), "sample_crossfade")
    loaded, problems = validate_text(text, str(tmp_path / "s.yaml"), tmp_path)
    assert loaded is not None
    (warning,) = [p for p in problems if p.path == ("directivity", "speech", "head_turn")]
    assert warning.severity == "warning" and "has no effect" in warning.message


def _with_interpolation(text: str, interpolation: str) -> str:
    """The demo spec with ``mixture.interpolation`` set (it leaves it at its default)."""
    assert "\nmixture:\n" in text and "interpolation:" not in text
    return text.replace("\nmixture:\n", f"\nmixture:\n  interpolation: {interpolation}\n")


def _moving_trajectory():
    from sonicspec.spec.trajectory import MicrophoneLineTrajectorySpec

    return MicrophoneLineTrajectorySpec(kind="line", start_m=(1.0, 1.0, 1.5),
                                        end_m=(2.0, 1.0, 1.5))


def test_a_sofa_talker_is_keyed_by_its_file_and_read_by_the_steps(tmp_path: Path) -> None:
    """A SOFA FreeFieldDirectivityTF file the test writes: its digest keys the rir step, both
    steps that need it get its path, and the steps read it as a measured pattern."""
    import numpy as np
    from test_directivity import _write_sofa

    from sonicspec.acoustics.directivity import SofaPattern
    from sonicspec.plan.params import RirParams
    from sonicspec.stages.directivity import source_patterns

    def cardioid(dirs, f):
        return np.repeat(0.5 + 0.5 * dirs[:, :1], len(f), axis=1)

    _write_sofa(tmp_path / "talker.sofa", cardioid, np.geomspace(50, 7000, 100))
    spec = _spec(tmp_path, "directivity:\n  speech: {pattern: sofa, sofa_path: talker.sofa}\n")
    plan = compile_spec(load_spec(spec), cache=False)
    rir = next(j for j in plan.jobs if j.step == "rir")
    render = next(j for j in plan.jobs if j.step == "render")
    assert len(rir.params["files"]["directivity_speech"]) == 64
    assert rir.paths["directivity_speech"] == str(tmp_path / "talker.sofa")
    if render.params["interpolation"] == "paths":
        assert render.paths["directivity_speech"] == str(tmp_path / "talker.sofa")
    params = RirParams.model_validate(rir.params)
    patterns = source_patterns(params.directivity, rir.paths, (250.0, 1000.0, 4000.0))
    assert set(patterns) == {"speech"} and isinstance(patterns["speech"], SofaPattern)
    back = patterns["speech"].gains(np.array([[-1.0, 0, 0], [0, 1.0, 0]]), (1000.0,))[:, 0]
    np.testing.assert_allclose(back, [0.0, 0.5], atol=0.02)


def _moving_line(n: int = 16000, pairs: int = 9):
    """A timeline of a source standing at (2, 0, 1.6) while the microphone walks from
    (0, -2, 1.5) to (0, 2, 1.5) over ``n`` samples, ``pairs`` pairs evenly spread."""
    import numpy as np

    from sonicspec.stages.motion import Timeline

    at = np.linspace(0, n - 1, pairs)
    mic = np.stack([np.zeros(pairs), np.linspace(-2, 2, pairs), np.full(pairs, 1.5)], 1)
    source = np.tile([2.0, 0.0, 1.6], (pairs, 1))
    index = np.interp(np.arange(n), at, np.arange(pairs, dtype=float))
    return Timeline(index, source, mic, np.zeros(pairs), 0.0, True), at


@pytest.mark.parametrize("facing", ["toward_mic", "walk"])
def test_a_standing_source_faces_a_moving_microphone_where_it_is(facing: str) -> None:
    """``toward_mic`` (and ``walk`` for a source that never walks) turns with a moving
    microphone: every 10 ms frame and every RIR pair faces where the microphone is then."""
    import numpy as np

    from sonicspec.stages.directivity import facing_frames, pair_yaws_deg

    line, at = _moving_line()
    d = DirectivitySpec(pattern="cardioid", facing=facing)
    hop, frames = facing_frames(d, line, None, 16000, None)
    mic = line.at(line.mic_m, line.index[::hop])
    bearing = np.degrees(np.unwrap(np.arctan2(mic[:, 1], mic[:, 0] - 2.0)))  # through 180°
    np.testing.assert_allclose(frames, bearing, atol=1e-9)
    pairs = pair_yaws_deg(d, line, 16000)
    # the facing track read at each pair's sample, as the render step reads it per sample
    # (linear between 10 ms frames, held after the last: the last pair is 159 samples on)
    seen = line.at(line.mic_m, np.interp(np.minimum(at, (len(frames) - 1) * hop),
                                         np.arange(line.index.size), line.index))
    expect = np.degrees(np.unwrap(np.arctan2(seen[:, 1], seen[:, 0] - 2.0)))
    assert np.ptp(expect) > 85  # it turns through nearly a right angle
    np.testing.assert_allclose(pairs, expect, atol=0.05)


def test_a_fixed_source_keeps_its_yaw_at_every_pair() -> None:
    import numpy as np

    from sonicspec.stages.directivity import pair_yaws_deg

    line, _ = _moving_line()
    d = DirectivitySpec(pattern="speech", facing="fixed", yaw_deg=-30.0)
    np.testing.assert_array_equal(pair_yaws_deg(d, line, 16000), -30.0)


def test_head_turns_without_the_paths_are_refused_by_compile_too(tmp_path: Path) -> None:
    """A spec changed in Python after validation: the compiler says what validate says."""
    loaded = load_spec(_spec(tmp_path, HEAD_TURN.replace("PATTERN", "speech")))
    crossfade = loaded.spec.model_copy(update={"mixture": loaded.spec.mixture.model_copy(
        update={"interpolation": "sample_crossfade"})})
    with pytest.raises(CompileError, match=r"directivity.speech.head_turn: head turns are "
                                           r"rendered .* got 'sample_crossfade'"):
        compile_spec(type(loaded)(**{**loaded.__dict__, "spec": crossfade}), cache=False)
