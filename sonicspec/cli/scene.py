"""Looking at a room: ``sonicspec scene inspect`` and ``sonicspec rir`` (one room impulse
response in a spec's scene, a scene file or a mesh file)."""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
from pathlib import Path

from sonicspec.cli.common import (
    EXIT_INVALID,
    EXIT_OK,
    load_or_exit,
    names_scene_file,
    plot_unavailable,
    print_problems,
)


def _choose_scene(loaded, args: argparse.Namespace) -> bool:
    """Fill ``args.scene`` when the spec has one scene; False (after a message) if ambiguous."""
    from sonicspec.stages.inspect import scene_ids

    if args.scene is None:
        ids = scene_ids(loaded)
        if len(ids) != 1:
            print(f"sonicspec: error: --scene: the spec has {len(ids)} scenes; choose one of "
                  f"{', '.join(ids)}", file=sys.stderr)
            return False
        args.scene = ids[0]
    return True


def cmd_scene_inspect(args: argparse.Namespace) -> int:
    from sonicspec.stages.inspect import inspect_scene

    if plot_unavailable(args):
        return EXIT_INVALID
    loaded = load_or_exit(args.spec)
    if loaded is None or not _choose_scene(loaded, args):
        return EXIT_INVALID
    facts = inspect_scene(loaded, args.scene, plot=Path(args.plot) if args.plot else None)
    print(json.dumps(facts.to_dict(), indent=2) if args.json else facts.format())
    return EXIT_OK


def cmd_rir(args: argparse.Namespace) -> int:

    if plot_unavailable(args):
        return EXIT_INVALID
    if (args.spec is None) == (args.mesh is None):
        print("sonicspec: error: rir: expected a SPEC or --mesh FILE, got "
              f"{'both' if args.spec else 'neither'}", file=sys.stderr)
        return EXIT_INVALID
    if args.mesh is not None:
        if args.scene is not None:
            print("sonicspec: error: --scene: expected a SPEC to choose a scene from, got "
                  "--mesh; the mesh is the scene", file=sys.stderr)
            return EXIT_INVALID
        report = _rir_of_mesh(args)
        if report is None:
            return EXIT_INVALID
        title = f"{Path(args.mesh).name}: source {args.source} -> mic {args.mic}"
    else:
        mesh_only = [flag for flag, value in (
            ("--material", args.material), ("--default-material", args.default_material),
            ("--library", args.library), ("--repair", args.repair), ("--rays", args.rays),
            ("--seed", args.seed), ("--sample-rate", args.sample_rate),
            ("--microphone", args.microphone))
            if value not in (None, False)]
        if mesh_only:
            print(f"sonicspec: error: {mesh_only[0]}: expected --mesh FILE with it, got a "
                  "SPEC (the spec sets materials, acoustics and the seed)", file=sys.stderr)
            return EXIT_INVALID
        if names_scene_file(args.spec):
            report = _rir_of_scene_file(args)
            if report is None:
                return EXIT_INVALID
            title = f"{report.scene_id}: source {args.source} -> mic {args.mic}"
        else:
            from sonicspec.stages.rir import rir_from_spec

            loaded = load_or_exit(args.spec)
            if loaded is None or not _choose_scene(loaded, args):
                return EXIT_INVALID
            report = rir_from_spec(loaded, args.scene, args.source, args.mic)
            title = f"{args.scene}: source {args.source} -> mic {args.mic}"
    for warning in report.warnings:
        print(f"sonicspec: warning: {warning}", file=sys.stderr)
    result = report.result
    if args.output:
        from sonicspec.export.files import write_audio

        write_audio(Path(args.output), result.rir, result.sample_rate_hz,
                    audio_format="wav", subtype="FLOAT")
        report = dataclasses.replace(report, output=args.output)
    if args.plot:
        from sonicspec.export.plots import plot_rir

        plot_rir(result.rir[0], result.sample_rate_hz, result.bands_hz, Path(args.plot),
                 title=title)
        report = dataclasses.replace(report, plot=args.plot)
    print(json.dumps(report.to_dict(), indent=2) if args.json else report.format())
    return EXIT_OK


def _rir_of_scene_file(args: argparse.Namespace):
    """``sonicspec rir SCENE.yaml``: the RIR and facts of a scene file through the Python API,
    or None after a message."""
    import warnings

    from sonicspec.api import RirSettings, Scene, compute_rir
    from sonicspec.errors import SonicspecError, SonicspecWarning
    from sonicspec.spec.validate import validate_scene_file
    from sonicspec.stages.rir import RirReport

    if args.scene is not None:
        print("sonicspec: error: --scene: a scene file holds one scene; --scene chooses one "
              "of a dataset spec's", file=sys.stderr)
        return None
    spec, problems = validate_scene_file(args.spec)
    print_problems(problems, args.spec)
    if spec is None:
        return None
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", SonicspecWarning)
        try:
            scene = Scene.from_spec(spec.scene, spec.materials,
                                    base_dir=Path(args.spec).resolve().parent, seed=spec.seed)
            settings = RirSettings(**spec.acoustics.model_dump(),
                                   sample_rate_hz=spec.sample_rate_hz,
                                   speed_of_sound_m_s=spec.speed_of_sound_m_s)
            result = compute_rir(scene, args.source, args.mic, settings,
                                 receiver=spec.microphone, seed=spec.seed)
        except SonicspecError as exc:
            print(f"sonicspec: error: {args.spec}: {exc}", file=sys.stderr)
            return None
    return RirReport(result, scene.name, scene.mesh.n_faces, tuple(
        str(w.message) for w in caught if issubclass(w.category, SonicspecWarning)),
        materials_m2=scene.material_areas_m2())


def _spec_default(section: str, field: str) -> object:
    """The spec's default of ``section.field`` (``""``: a top-level field), for help texts: a
    default is written once, in the spec models."""
    from sonicspec.spec.dataset import DatasetSpec

    model = DatasetSpec
    if section:
        model = DatasetSpec.model_fields[section].default_factory().__class__
    return model.model_fields[field].get_default(call_default_factory=True)


def _rir_of_mesh(args: argparse.Namespace):
    """``sonicspec rir --mesh``: the RIR and facts through the Python API, or None after a
    message when the mesh, a label or a material name is wrong."""
    import warnings

    from pydantic import ValidationError

    from sonicspec.api import RirSettings, Scene, compute_rir
    from sonicspec.errors import SonicspecError, SonicspecWarning
    from sonicspec.stages.rir import RirReport

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", SonicspecWarning)
        try:
            scene = Scene.from_file(args.mesh, dict(args.material or []),
                                    default_material=args.default_material,
                                    library=args.library or "sonicspec", repair=args.repair)
        except SonicspecError as exc:
            print(f"sonicspec: error: {exc}", file=sys.stderr)
            return None
        flags = {"rays": ("--rays", args.rays), "sample_rate_hz": ("--sample-rate",
                                                                   args.sample_rate)}
        try:
            settings = RirSettings(**{k: v for k, (_, v) in flags.items() if v is not None})
        except ValidationError as exc:
            error = exc.errors()[0]
            print(f"sonicspec: error: {flags[error['loc'][0]][0]}: {error['msg'].lower()}, got "
                  f"{error['input']}", file=sys.stderr)
            return None
        receiver = _microphone_option(args.microphone)
        if receiver is False:
            return None
        result = compute_rir(scene, args.source, args.mic, settings, receiver=receiver,
                             seed=args.seed or 0)
    return RirReport(result, scene.name, scene.mesh.n_faces, tuple(
        str(w.message) for w in caught if issubclass(w.category, SonicspecWarning)),
        materials_m2=scene.material_areas_m2())


def _microphone_option(text: str | None):
    """``--microphone "{kind: ambisonics, order: 1}"``: the spec's microphone model (None:
    mono), or False after a message when the text is not one."""
    if text is None:
        return None
    import yaml
    from pydantic import TypeAdapter, ValidationError

    from sonicspec.spec.microphone import MicrophoneSpec

    try:
        value = yaml.safe_load(text)
        if not isinstance(value, dict):
            raise ValueError(f"expected a mapping such as '{{kind: ambisonics, order: 1}}', "
                             f"got {text!r}")
        return TypeAdapter(MicrophoneSpec).validate_python(value)
    except (yaml.YAMLError, ValueError) as exc:
        if isinstance(exc, ValidationError):
            error = exc.errors()[0]
            where = ".".join(str(x) for x in error["loc"])
            exc = f"{where}: {error['msg'].lower()}" if where else error["msg"].lower()
        print(f"sonicspec: error: --microphone: {exc}", file=sys.stderr)
        return False


def _label_material(text: str) -> tuple[str, str]:
    label, sep, name = text.partition("=")
    if not sep or not label or not name:
        raise argparse.ArgumentTypeError(f"expected LABEL=NAME, got {text!r}")
    return label, name


def add_scene(sub) -> None:
    """``sonicspec scene inspect SPEC``."""
    p = sub.add_parser("scene", help="look at the scenes of a spec")
    scene_sub = p.add_subparsers(dest="scene_command", metavar="ACTION")
    scene_sub.required = True
    p = scene_sub.add_parser("inspect", help="mesh statistics, repair report, materials, "
                             "floors, walkable area and a floor-plan picture")
    p.add_argument("spec", metavar="SPEC")
    p.add_argument("--scene", metavar="ID", help="scene id (required if the spec has several)")
    p.add_argument("--plot", metavar="FILE.png", help="draw the floor plan with a sampled group")
    p.add_argument("--json", action="store_true", help="print the facts as one JSON object")
    p.set_defaults(func=cmd_scene_inspect)


def add_rir(sub) -> None:
    """``sonicspec rir``."""
    p = sub.add_parser("rir", help="one room impulse response, in a spec's scene or in a mesh "
                       "file, with T30, EDT, C50 and DRR")
    p.add_argument("spec", metavar="SPEC", nargs="?",
                   help="a dataset spec (or give --mesh instead)")
    p.add_argument("--scene", metavar="ID", help="scene id (required if the spec has several)")
    p.add_argument("--source", nargs=3, type=float, required=True, metavar=("X", "Y", "Z"),
                   help="source position, metres")
    p.add_argument("--mic", nargs=3, type=float, required=True, metavar=("X", "Y", "Z"),
                   help="microphone position, metres")
    p.add_argument("-o", "--output", metavar="RIR.wav", help="write the RIR (float32 WAV)")
    p.add_argument("--plot", metavar="FILE.png", help="waveform, decay curves, arrivals")
    p.add_argument("--json", action="store_true", help="print the figures as one JSON object")
    g = p.add_argument_group("without a spec", "a mesh file (glb, gltf, obj, ply; metres, "
                             "z up for obj/ply) whose labels (object or group names, PLY "
                             "face labels) map to materials; the spec's acoustics defaults")
    g.add_argument("--mesh", metavar="FILE", help="the room's mesh file")
    g.add_argument("--material", metavar="LABEL=NAME", action="append", type=_label_material,
                   help="material of a label (repeat for each label)")
    g.add_argument("--default-material", metavar="NAME",
                   help="material of faces without a label")
    g.add_argument("--library", choices=("sonicspec", "sonicset"),
                   help="material library (default: sonicspec)")
    g.add_argument("--repair", action="store_true",
                   help="repair the mesh first (off: the mesh is traced as given)")
    g.add_argument("--rays", type=int, metavar="N",
                   help=f"rays traced (default: {_spec_default('acoustics', 'rays')})")
    g.add_argument("--seed", type=int, metavar="N", help="random seed (default: 0)")
    g.add_argument("--sample-rate", type=int, metavar="HZ",
                   help=f"sample rate (default: {_spec_default('', 'sample_rate_hz')})")
    g.add_argument("--microphone", metavar="YAML",
                   help="the receiver as the spec writes it, e.g. '{kind: ambisonics, order: 1}'"
                   " or '{kind: circular_array, n: 6, radius_m: 0.05}' (default: mono)")
    p.set_defaults(func=cmd_rir)
