"""The package map of DESIGN.md §2 and docs/architecture.md, checked on the source: who may
import whom.

Every module under ``sonicspec/`` is parsed with ``ast``; every import counts, lazy ones inside
functions included. Floors, from the ground up:

* ground floor: the modules at the package's top (``errors``, ``units``, ``hashing``,
  ``atomic``, ``shares``, ...; not ``cli``) import nothing of sonicspec above them;
* ``spec`` (the language) and ``store`` stand on the ground floor only;
* the libraries ``geometry``, ``acoustics``, ``audio`` stand on the ground floor and on each
  other, never on the spec, the store or anything above (``acoustics`` has floors of its own:
  the pipeline of one RIR its package docstring draws);
* ``plan`` (the compiler) stands on the spec, the store and the libraries;
* ``artifacts`` (what steps hand each other: the codec of every artifact kind, and the scene
  mesh a mesh job builds) stands on the spec, the libraries and the plan's params;
* ``stages``, ``export``, the Python API (``api``) and then ``cli`` are above them; nothing
  below imports up, and **nothing outside ``stages/`` and ``cli/`` imports ``stages``** (the
  one-way rule: the pipeline's steps are an entry, never a library);
* ``dataload`` (the loader, evaluation and exports) reads built dataset folders: it stands on
  the ground floor, the libraries and ``export``, never on the spec, the store or the pipeline;
* ``testing`` holds test fixtures: it may use the libraries, and nothing in the package uses it.
"""

from __future__ import annotations

import ast
from collections.abc import Iterator
from functools import cache
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[1] / "sonicspec"
ROOT = PACKAGE.parent

LIBRARIES = {"geometry", "acoustics", "audio"}
UPPER = {"stages", "plan", "artifacts", "export", "dataload", "cli", "testing"}

KNOWN_CYCLES: list[set[str]] = []


@cache
def modules() -> dict[str, Path]:
    out = {}
    for path in sorted(PACKAGE.rglob("*.py")):
        parts = list(path.relative_to(ROOT).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        out[".".join(parts)] = path
    return out


@cache
def tree(module: str) -> ast.Module:
    return ast.parse(modules()[module].read_text(encoding="utf-8"))


def _owner(name: str) -> str | None:
    """The sonicspec module ``name`` lives in (an imported function resolves to its module)."""
    while name and name not in modules():
        name = name.rpartition(".")[0]
    return name or None


def imports(module: str) -> Iterator[tuple[str, int]]:
    """(imported sonicspec module, line) for every import in ``module``, lazy ones too."""
    is_package = modules()[module].name == "__init__.py"
    for node in ast.walk(tree(module)):
        if isinstance(node, ast.Import):
            names = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                parts = module.split(".")[: len(module.split(".")) - node.level + is_package]
                base = ".".join(parts + ([node.module] if node.module else []))
            names = [f"{base}.{a.name}" for a in node.names]
        else:
            continue
        for name in names:
            if name.split(".")[0] != "sonicspec":
                continue
            target = _owner(name)
            if target is not None and target != module:
                yield target, node.lineno


def floor(module: str) -> str:
    """``ground``, a subpackage's name, or ``cli``."""
    parts = module.split(".")
    if len(parts) == 1:
        return "ground"  # the package itself (its __version__)
    if (PACKAGE / parts[1]).is_dir():
        return parts[1]
    # The command line and the Python API (a facade over the libraries) stand at the top.
    return "cli" if parts[1] in ("cli", "api") else "ground"


def edges() -> list[tuple[str, str, int]]:
    return [(m, t, line) for m in modules() for t, line in imports(m)]


def _where(module: str, line: int) -> str:
    return f"{modules()[module].relative_to(ROOT)}:{line}"


# ``sonicspec.Scene`` and friends: the package reaches the API only when such a name is asked
# for (PEP 562 ``__getattr__``), so ``import sonicspec`` stays light.
ALLOWED_EDGES = {("sonicspec", "sonicspec.api")}


def _offences(allowed: dict[str, set[str]]) -> list[str]:
    return [f"{_where(a, line)}: {a} imports {b}" for a, b, line in edges()
            if floor(a) in allowed and floor(b) not in allowed[floor(a)]
            and (a, b) not in ALLOWED_EDGES]


def test_the_map_sees_every_floor() -> None:
    floors = {floor(m) for m in modules()}
    assert floors >= {"ground", "spec", "store", *LIBRARIES, *UPPER}
    assert {"sonicspec.errors", "sonicspec.units", "sonicspec.hashing",
            "sonicspec.atomic"} <= {m for m in modules() if floor(m) == "ground"}
    # lazy imports count: stages/corpus imports the generated corpora inside a function
    assert ("sonicspec.audio.generated" in
            {t for t, _ in imports("sonicspec.stages.corpus")})


def test_nothing_below_imports_up() -> None:
    lower = {"ground", "spec", "store", *LIBRARIES}
    assert _offences({f: lower for f in lower}) == []


def test_ground_spec_and_store_stand_on_the_ground_floor() -> None:
    assert _offences({"ground": {"ground"}, "spec": {"ground", "spec"},
                      "store": {"ground", "store"}}) == []


def test_libraries_know_nothing_of_the_spec_or_the_store() -> None:
    allowed = {"ground", *LIBRARIES}
    assert _offences({f: allowed for f in LIBRARIES}) == []


def test_plan_and_artifacts_stand_below_the_stages_and_the_export() -> None:
    assert _offences({"plan": {"ground", "spec", "store", *LIBRARIES, "plan"}}) == []
    assert _offences({"artifacts": {"ground", "spec", *LIBRARIES, "plan", "artifacts"}}) == []
    # the export (report, plots) decodes artifacts through the codecs, not the stages
    assert {"sonicspec.artifacts"} <= {t for t, _ in imports("sonicspec.export.report_data")}


def test_nothing_outside_stages_and_cli_imports_stages() -> None:
    # The one-way rule: the steps read the codecs and the libraries below them; the report,
    # the Python API and the libraries never reach up into the steps. (workflow/rules/common.smk
    # runs sonicspec.stages.workflow: the workflow is an entry, like the command line.)
    def inside(module: str, package: str) -> bool:
        return module == package or module.startswith(package + ".")

    offences = [f"{_where(a, line)}: {a} imports {b}" for a, b, line in edges()
                if inside(b, "sonicspec.stages")
                and not (inside(a, "sonicspec.stages") or inside(a, "sonicspec.cli"))]
    assert offences == []


def test_docs_architecture_maps_every_floor() -> None:
    # docs/architecture.md draws these floors for people: every floor, every package of
    # sonicspec/ and every acoustics subpackage named here is on the page, and so is the rule.
    text = (ROOT / "docs" / "architecture.md").read_text(encoding="utf-8")
    packages = {p.name for p in PACKAGE.iterdir() if (p / "__init__.py").is_file()}
    acoustics = {p.name for p in (PACKAGE / "acoustics").iterdir() if (p / "__init__.py").is_file()}
    named = {*LIBRARIES, *UPPER, "spec", "store", "api", *packages}
    assert [n for n in sorted(named) if f"`{n}/`" not in text and f"`{n}`" not in text] == []
    assert [n for n in sorted(acoustics | set(ACOUSTICS) - {"basics"})
            if f"`{n}/`" not in text and f"`{n}`" not in text] == []
    assert "nothing outside `stages/` and `cli/` imports `stages/`" in " ".join(text.split())


def test_dataload_reads_folders_not_the_pipeline() -> None:
    allowed = {"ground", *LIBRARIES, "export", "dataload"}
    assert _offences({"dataload": allowed}) == []
    assert "sonicspec.dataload.folder" in {t for t, _ in imports("sonicspec.dataload.loader")}


def test_nothing_in_the_package_imports_testing() -> None:
    assert [f"{_where(a, line)}: {a} imports {b}" for a, b, line in edges()
            if floor(b) == "testing" and floor(a) != "testing"] == []
    workflow = ROOT / "workflow"
    assert [p for p in workflow.rglob("*") if p.is_file()
            and "sonicspec.testing" in p.read_text(encoding="utf-8", errors="replace")] == []


# The acoustics library's own floors, as sonicspec/acoustics/__init__.py draws the pipeline of
# one RIR: the shared basics at its top (bands, air, arrivals, directions, metrics and the
# references in theory), the room on Embree, the exact paths, the stochastic late field, the
# receivers, the moving paths, and the engine, which runs them all.
ACOUSTICS = {
    "basics": {"basics"},
    "room": {"basics", "room"},
    "paths": {"basics", "room", "paths"},
    "late": {"basics", "room", "paths", "late"},
    "receivers": {"basics", "receivers"},
    "moving": {"basics", "receivers", "moving"},
    "engine": {"basics", "room", "paths", "late", "receivers", "moving", "engine"},
}


def acoustics_floor(module: str) -> str:
    """``engine``, an acoustics subpackage's name, or ``basics`` (the modules at its top)."""
    parts = module.split(".")
    if len(parts) >= 3 and (PACKAGE / "acoustics" / parts[2]).is_dir():
        return parts[2]
    return "engine" if parts[2:] == ["engine"] else "basics"


def test_acoustics_imports_go_down_its_pipeline() -> None:
    inside = [m for m in modules() if floor(m) == "acoustics"]
    assert {acoustics_floor(m) for m in inside} == set(ACOUSTICS)
    assert acoustics_floor("sonicspec.acoustics.theory") == "basics"
    assert acoustics_floor("sonicspec.acoustics.late._trace_kernels") == "late"
    offences = [f"{_where(a, line)}: {a} imports {b}" for a, b, line in edges()
                if floor(a) == floor(b) == "acoustics"
                and acoustics_floor(b) not in ACOUSTICS[acoustics_floor(a)]]
    assert offences == []
    # The package docstring draws every subpackage and names the references.
    drawing = ast.get_docstring(tree("sonicspec.acoustics")) or ""
    subpackages = sorted(p.name for p in (PACKAGE / "acoustics").iterdir()
                         if (p / "__init__.py").is_file())
    assert [s for s in subpackages if f"{s}/" not in drawing] == []
    assert "sonicspec.acoustics.theory" in drawing


def _cycles() -> list[set[str]]:
    """Strongly connected components of more than one module (Tarjan)."""
    graph: dict[str, set[str]] = {m: set() for m in modules()}
    for a, b, _ in edges():
        graph[a].add(b)
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    out: list[set[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in sorted(graph[v]):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = set()
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.add(w)
                if w == v:
                    break
            if len(component) > 1:
                out.append(component)

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return out


def test_no_module_cycles() -> None:
    assert [c for c in _cycles() if c not in KNOWN_CYCLES] == []


def _calls(module: str, owner: str, names: set[str]) -> list[int]:
    return [node.lineno for node in ast.walk(tree(module))
            if isinstance(node, ast.Attribute) and node.attr in names
            and isinstance(node.value, ast.Name) and node.value.id == owner]


def test_one_hashing_module_one_atomic_writer_one_speed_of_sound() -> None:
    hashing = [m for m in modules() for node in ast.walk(tree(m))
               if isinstance(node, (ast.Import, ast.ImportFrom))
               and "hashlib" in ([a.name for a in node.names] if isinstance(node, ast.Import)
                                 else [node.module])]
    assert hashing == ["sonicspec.hashing"]
    # Files are renamed into place by sonicspec.atomic; the store renames its Zarr folders.
    renames = {m for m in modules() if _calls(m, "os", {"replace", "rename"})}
    assert renames == {"sonicspec.atomic", "sonicspec.store.artifacts"}
    speeds = [_where(m, node.lineno) for m in modules() for node in ast.walk(tree(m))
              if isinstance(node, ast.Constant) and type(node.value) in (int, float)
              and node.value == 343]
    assert [s.partition(":")[0] for s in speeds] == ["sonicspec/units.py"]


def _stage_modules() -> list[str]:
    return [m for m in modules() if m.startswith("sonicspec.stages.")]


def _is_params(node: ast.AST) -> bool:
    """``params``, ``x.params`` or ``x.params[...]`` (a job's parameters in any form)."""
    return ((isinstance(node, ast.Name) and node.id == "params")
            or (isinstance(node, ast.Attribute) and node.attr == "params"))


def test_stages_read_parameters_as_typed_fields() -> None:
    # Issue 17: no stage looks a parameter up by string; each reads its step's params model.
    lookups = []
    for m in _stage_modules():
        for node in ast.walk(tree(m)):
            if isinstance(node, ast.Subscript) and _is_params(node.value):
                lookups.append(_where(m, node.lineno))
            if (isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute)
                    and node.func.attr == "get" and _is_params(node.func.value)):
                lookups.append(_where(m, node.lineno))
    assert lookups == []


def test_a_stage_decodes_artifacts_only_through_sonicspec_artifacts() -> None:
    # Issue 17: a stage does not import the producing stage's module to read its artifact;
    # every artifact's encoding lives in sonicspec.artifacts, below the stages and the export.
    # (corpus and mesh serve other stages with functions of their own: corpus roots, and the
    # scene a command shows.)
    runners = {"mesh", "navigation", "placement", "arrange", "rir", "render", "mix", "export",
               "dataset"}
    offences = [
        f"{_where(a, line)}: {a} imports {b}" for a, b, line in edges()
        if a.rpartition(".")[2] in runners and a.startswith("sonicspec.stages.")
        and b.startswith("sonicspec.stages.") and b.rpartition(".")[2] in runners
    ]
    assert offences == []
    assert "sonicspec.artifacts" in {t for t, _ in imports("sonicspec.stages.rir")}


def _string_lookups(source: ast.AST) -> list[tuple[int, str, str]]:
    """``(line, receiver, key)`` of every ``x["key"]`` read and ``x.get("key", ...)`` in
    ``source`` (writes, ``x["key"] = ...``, build a record and are not counted)."""
    out = []
    for node in ast.walk(source):
        if (isinstance(node, ast.Subscript) and isinstance(node.ctx, ast.Load)
                and isinstance(node.slice, ast.Constant) and isinstance(node.slice.value, str)):
            out.append((node.lineno, ast.unparse(node.value), node.slice.value))
        elif (isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute)
              and node.func.attr == "get" and node.args and isinstance(node.args[0], ast.Constant)
              and isinstance(node.args[0].value, str)):
            out.append((node.lineno, ast.unparse(node.func.value), node.args[0].value))
    return out


# Issue 29: the string lookups left in stages/ once the RIR facts (RirFacts, TailFacts,
# EdgeChoice), the placement (GroupPlacement), the mix levels, the metadata's segments and
# mixtures and the `sonicspec rir` / `scene inspect` reports were typed (225 on main before,
# 105 after). Each (module, receiver) is a map keyed by data — a role, a kind of signal, a
# named input file, a figure — or a record not typed yet, said why. A lookup on any other
# receiver fails: read a typed field instead, or add the receiver here with its reason.
KEYED_BY_DATA = {
    ("arrange", "indexes"): "corpus index per role",
    ("corpus", "ctx.job.paths"): "the plan's named input paths (Job.paths)",
    ("corpus", "job.paths"): "the plan's named input paths",
    ("corpus", "paths"): "the plan's named input paths",
    ("corpus", "plan.by_step()"): "jobs per step",
    ("render", "ctx.job.paths"): "the plan's named input paths",
    ("rir", "ctx.job.paths"): "the plan's named input paths",
    ("render", "signals"): "rendered signals per kind (reverberant, direct, early)",
    ("render", "point"): "a point source's rendered signals per kind (diffuse backgrounds)",
    ("render", "out"): "a diffuse background's signals per kind",
    ("mix", "track.arrays"): "a rendered track's array name per kind (RenderedTrack.arrays)",
    ("export", "track.arrays"): "a rendered track's array name per kind",
    ("export", "tracks[c].arrays"): "a rendered track's array name per kind",
    ("export", "entries"): "metadata tracks per name (noise, music)",
    ("rir", "broadband"): "the library's broadband figures per name (RoomAcousticFigures)",
    ("rir", "first.broadband"): "the library's broadband figures per name",
    ("workflow", "env"): "environment variables",
    ("workflow", "result.not_made"): "unfinished jobs per step",
    ("dataset", "self.files"): "a split's open manifest files per name (recordings, "
                               "supervisions)",
}
NOT_TYPED_YET = {
    # the corpus artifact's skipped files (the dataset step's and the build summary's), the
    # dataset folder's marker and a dataset artifact's provenance, read by repair. (The export
    # and dataset steps' file and group records and checked.json are typed since:
    # sonicspec.artifacts.records; the mesh step's report: sonicspec.artifacts.mesh_report.)
    ("dataset", "ctx.store.read_data('corpus', k)"), ("corpus", "data"),
    ("repair", "marker"), ("repair", "store.read('dataset', key).provenance"),
    ("workflow", "files[0]"),
    # plan --summary's image-source outlook per scene (the --json output, built and printed
    # as dicts); next: an ImageSourceOutlook record with to_dict()
    ("inspect", "e"), ("inspect", "est"), ("inspect", "entry"), ("inspect", "e['estimate'] or {}"),
    ("inspect", "scenes[0]"), ("inspect", "spec.materials.model_dump(mode='json')"),
    # the batch layout file (batches of shards: units with members and a header), written by
    # the head and read by the batch job and the Snakefile; next: a BatchLayout model
    ("batch", "header"), ("batch", "unit"), ("workflow", "self.layout.units[wildcards.key]"),
    ("workflow", "unit"), ("workflow", "u"),
}
# 110 after the morning's merges (+4 a diffuse background's signals per kind, +1 a facing
# array), +38 the image-source outlook, +15 the batch layout: 163; -46 the export and dataset
# steps' file and group records and checked.json typed, -26 the mesh step's report typed.
STRING_LOOKUPS_LEFT = 91


def test_stages_read_rir_facts_and_placements_as_typed_fields() -> None:
    found = [(m.rpartition(".")[2], line, receiver, key) for m in _stage_modules()
             for line, receiver, key in _string_lookups(tree(m))]
    unknown = [f"sonicspec/stages/{m}.py:{line}: {receiver}[{key!r}]"
               for m, line, receiver, key in found
               if (m, receiver) not in KEYED_BY_DATA and (m, receiver) not in NOT_TYPED_YET]
    assert unknown == []
    # the count only goes down: lower it when a record above gets its model
    assert len(found) == STRING_LOOKUPS_LEFT
    # the RIR step and the placement read none but named inputs and the library's figures
    assert {r for m, _, r, _ in found if m in ("rir", "placement", "motion", "render")} == {
        "ctx.job.paths", "broadband", "first.broadband", "signals", "point", "out"}


def test_the_string_lookup_counter_sees_reads_and_gets() -> None:
    sample = ast.parse("a = facts['direct']\nb = facts.get('tail', {})\nfacts['x'] = 1\n"
                       "c = facts.direct\nd = arrays[key]\n")
    assert _string_lookups(sample) == [(1, "facts", "direct"), (2, "facts", "tail")]
