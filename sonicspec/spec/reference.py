"""The spec reference as Markdown, generated from the models' JSON Schema.

The documentation site's spec reference is this function's output (the site's build hook calls
it), so every field's type, unit, default, range and description is written once, in the
models. One section per model, in the order a spec file meets them; a field whose type is
another model links to that model's section.
"""

from __future__ import annotations

import json
import re
from typing import Any

from pydantic import BaseModel

from sonicspec.spec.dataset import SPEC_VERSION, DatasetSpec
from sonicspec.spec.scene_file import SceneFileSpec
from sonicspec.spec.schema import _constrain_keys, json_schema

# The unit a field's name ends in (STYLE.md: units are in field names), longest first.
UNIT_SUFFIXES = (
    ("_m_s", "m/s"),
    ("_m2", "m²"),
    ("_dbfs", "dBFS"),
    ("_lufs", "LUFS"),
    ("_deg", "degrees"),
    ("_pct", "%"),
    ("_hz", "Hz"),
    ("_db", "dB"),
    ("_lu", "LU"),
    ("_m", "m"),
    ("_s", "s"),
    ("_c", "°C"),
)


def unit_of(field: str) -> str:
    """The unit a field name states by its suffix (``size_m`` → ``m``), or ``""``."""
    for suffix, unit in UNIT_SUFFIXES:
        if field.endswith(suffix):
            return unit
    return ""


def anchor(model: str) -> str:
    """The heading id of a model's section."""
    return model.lower()


def models_in(root: type[BaseModel]) -> dict[str, type[BaseModel]]:
    """Every spec model reachable from ``root``, by class name (the schema's ``$defs`` keys)."""
    out: dict[str, type[BaseModel]] = {}

    def visit(tp: Any) -> None:
        if isinstance(tp, type) and issubclass(tp, BaseModel):
            if tp.__name__ in out:
                return
            out[tp.__name__] = tp
            for info in tp.model_fields.values():
                visit(info.annotation)
            return
        for arg in getattr(tp, "__args__", ()) or ():
            visit(arg)
        origin = getattr(tp, "__origin__", None)
        if origin is not None and hasattr(tp, "__metadata__"):
            visit(origin)

    visit(root)
    return out


def _cell(text: str) -> str:
    """Text safe inside a Markdown table cell: pipes escaped, ``<`` outside code not a tag."""
    parts = re.split(r"(`[^`]*`)", " ".join(text.split()))
    return "".join(part if part.startswith("`") else part.replace("<", "&lt;")
                   for part in parts).replace("|", "\\|")


def _code(value: Any) -> str:
    text = json.dumps(value, ensure_ascii=False, separators=(", ", ": "))
    return "`" + text.replace("|", "\\|") + "`"


def _ref_name(ref: str) -> str:
    return ref.rsplit("/", 1)[-1]


def _link(name: str) -> str:
    return f"[{name}](#{anchor(name)})"


def _bounds(p: dict[str, Any]) -> list[str]:
    out = []
    for key, sign in (("exclusiveMinimum", ">"), ("minimum", "≥"),
                      ("exclusiveMaximum", "<"), ("maximum", "≤")):
        if key in p:
            out.append(f"{sign} {p[key]:g}" if isinstance(p[key], float) else f"{sign} {p[key]}")
    return out


def type_text(p: dict[str, Any]) -> str:
    """A field's type in words, models as links to their sections."""
    if "$ref" in p:
        return _link(_ref_name(p["$ref"]))
    if "oneOf" in p:
        kinds = p.get("discriminator", {}).get("mapping", {})
        if kinds:
            return "one of, by `kind`: " + ", ".join(
                f"[{kind}](#{anchor(_ref_name(ref))})" for kind, ref in kinds.items())
        return " or ".join(type_text(x) for x in p["oneOf"])
    if "anyOf" in p:
        return " or ".join(type_text(x) for x in p["anyOf"])
    if "const" in p:
        return _code(p["const"])
    if "enum" in p:
        return " or ".join(_code(v) for v in p["enum"])
    kind = p.get("type")
    if kind == "array":
        if "prefixItems" in p:
            return "[" + ", ".join(type_text(x) for x in p["prefixItems"]) + "]"
        if isinstance(p.get("items"), dict):
            return "list of " + type_text(p["items"])
        return "list"
    if kind == "object":
        value = p.get("additionalProperties")
        if isinstance(value, dict):
            return "map of name → " + type_text(value)
        return "mapping"
    if kind == "null":
        return "`null`"
    return str(kind) if kind else "any"


def constraint_text(p: dict[str, Any]) -> str:
    """The range and other constraints of a field, in short words."""
    parts = [" and ".join(_bounds(p))] if _bounds(p) else []
    if "minLength" in p or "maxLength" in p:
        lo, hi = p.get("minLength", 0), p.get("maxLength")
        parts.append(f"length at least {lo}" if hi is None else f"length {lo}–{hi}")
    if "pattern" in p:
        parts.append(f"matches `{p['pattern']}`")
    if "minItems" in p or "maxItems" in p:
        lo, hi = p.get("minItems", 0), p.get("maxItems")
        if lo == hi:
            parts.append(f"{lo} items")
        elif hi is None:
            parts.append(f"at least {lo} item{'s' if lo != 1 else ''}")
        else:
            parts.append(f"{lo}–{hi} items")
    if "minProperties" in p:
        n = p["minProperties"]
        parts.append(f"at least {n} entr{'ies' if n != 1 else 'y'}")
    if isinstance(p.get("propertyNames"), dict):
        names = constraint_text(p["propertyNames"])
        if names:
            parts.append(f"names: {names}")
    if "prefixItems" in p:
        each = {constraint_text(x) for x in p["prefixItems"]}
        if len(each) == 1 and "" not in each:
            parts.append(f"each {each.pop()}")
        elif each != {""}:
            parts.append("; ".join(f"[{i}] {constraint_text(x) or 'any'}"
                                   for i, x in enumerate(p["prefixItems"])))
    if isinstance(p.get("items"), dict) and "$ref" not in p["items"] \
            and "oneOf" not in p["items"]:
        inner = constraint_text(p["items"])
        if inner:
            parts.append(f"items: {inner}")
    for branch in p.get("anyOf", []):
        inner = constraint_text(branch)
        if inner:
            parts.append(f"{type_text(branch)}: {inner}")
    return "; ".join(parts)


def _plain(value: Any) -> Any:
    """A default as the spec would write it: models with only their non-default fields."""
    if isinstance(value, BaseModel):
        return {k: _plain(v) for k, v in value.model_dump(exclude_defaults=True).items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items()}
    return value


def _default_text(model: type[BaseModel] | None, field: str, p: dict[str, Any],
                  required: bool) -> str:
    if required:
        return "required"
    if "default" in p:
        return _code(p["default"])
    info = model.model_fields.get(field) if model is not None else None
    if info is not None and info.default_factory is not None:
        value = _plain(info.default_factory())  # type: ignore[call-arg]
        return "its own defaults" if value == {} else _code(value)
    return "—"


def _walk_order(schema: dict[str, Any], root: str) -> list[tuple[str, list[str]]]:
    """Models in the order a spec meets them (depth first), each with the paths using it."""
    defs = schema.get("$defs", {})
    order: list[str] = []
    paths: dict[str, list[str]] = {}

    def refs(p: Any) -> list[str]:
        if isinstance(p, dict):
            found = [_ref_name(p["$ref"])] if "$ref" in p else []
            for key in ("oneOf", "anyOf"):
                for x in p.get(key, []):
                    found += refs(x)
            for key in ("items", "additionalProperties"):
                if isinstance(p.get(key), dict):
                    found += refs(p[key])
            return found
        return []

    def suffix(p: dict[str, Any]) -> str:
        if p.get("type") == "array" or any(x.get("type") == "array"
                                           for x in p.get("anyOf", [])):
            return "[]"
        if p.get("type") == "object":
            return ".<name>"
        return ""

    def visit(name: str, node: dict[str, Any], path: str) -> None:
        paths.setdefault(name, [])
        if path and path not in paths[name]:
            paths[name].append(path)
        if name in order:
            return
        order.append(name)
        for field, p in node.get("properties", {}).items():
            here = f"{path}.{field}" if path else field
            for ref in refs(p):
                visit(ref, defs[ref], here + suffix(p))

    visit(root, schema, "")
    return [(name, paths[name]) for name in order]


def model_section(name: str, node: dict[str, Any], model: type[BaseModel] | None,
                  used_at: list[str]) -> list[str]:
    """The Markdown of one model: its heading, where it is used, its fields' table."""
    lines = [f"### {name} {{#{anchor(name)}}}", ""]
    if used_at:
        lines += ["Used at: " + ", ".join(f"`{p}`" for p in used_at[:6])
                  + (f" and {len(used_at) - 6} more" if len(used_at) > 6 else ""), ""]
    if node.get("description"):
        lines += [" ".join(node["description"].split()), ""]
    required = set(node.get("required", []))
    # The site's stylesheet lays out tables inside a ``field-table`` block (md_in_html).
    lines += ['<div class="field-table" markdown>', "",
              "| field | type | unit | default | description and range |",
              "| --- | --- | --- | --- | --- |"]
    for field, p in node.get("properties", {}).items():
        text = " ".join(p.get("description", "").split())
        limits = constraint_text(p)
        if limits:
            text = f"{text} *Range:* {limits}." if text else f"*Range:* {limits}."
        lines.append("| " + " | ".join([
            f"`{field}`", _cell(type_text(p)), unit_of(field),
            _cell(_default_text(model, field, p, field in required)), _cell(text),
        ]) + " |")
    return [*lines, "", "</div>", ""]


def scene_file_schema() -> dict[str, Any]:
    """The JSON Schema of a scene file (``sonicspec rir SCENE.yaml``)."""
    schema = SceneFileSpec.model_json_schema(mode="validation")
    _constrain_keys(schema)
    return schema


def spec_reference() -> str:
    """The spec reference (the page's body, below its title): the dataset spec, the scene file."""
    models = {**models_in(DatasetSpec), **models_in(SceneFileSpec)}
    schema = json_schema()
    lines = [
        f"Every field of the spec language, version {SPEC_VERSION}, generated from the models"
        " (`sonicspec/spec/`) and their JSON Schema (`schema/sonicspec-v1.schema.json`,"
        " `sonicspec schema`). A *unit* is the one the field's name ends in: `_m` metres,"
        " `_s` seconds, `_hz` hertz, `_db` decibels, `_dbfs` dB full scale, `_lufs` LUFS,"
        " `_lu` loudness units, `_deg` degrees, `_m_s` metres per second, `_m2` square"
        " metres. Polymorphic sections choose their model by `kind`. A default shown as"
        " \"its own defaults\" is the section with every field at its default. Ranges are"
        " inclusive (`≥`, `≤`) or strict (`>`, `<`); `[min, max]` ranges are drawn"
        " uniformly and need min ≤ max. Cross-field rules (ranges ordered, names known,"
        " scenes disjoint across splits, positions inside rooms) are checked by"
        " `sonicspec validate` once the structure is valid.",
        "",
        "## Dataset spec",
        "",
    ]
    defs = schema["$defs"]
    for name, used_at in _walk_order(schema, "DatasetSpec"):
        node = schema if name == "DatasetSpec" else defs[name]
        lines += model_section(name, node, models.get(name), used_at)
    scene = scene_file_schema()
    lines += [
        "## Scene file",
        "",
        "A scene file declares one scene and how to compute RIRs in it (`sonicspec rir"
        " SCENE.yaml`, `sonicspec validate SCENE.yaml`); its sections are the dataset spec's"
        " own models, linked above.",
        "",
    ]
    lines += model_section("SceneFileSpec", scene, SceneFileSpec, [])
    return "\n".join(lines).rstrip() + "\n"
