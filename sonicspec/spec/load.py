"""Reading spec files: YAML/JSON with line numbers, validation, and messages people can act on.

A spec is parsed with PyYAML's composer so every value keeps the line and column it came from.
Validation errors from pydantic and from the semantic checks are turned into
:class:`Problem` objects that name the file, the line, the column, the field path and the fix:

    specs/x.yaml:14:5: scenes[1].size_m: all values must be > 0 and <= 1000 (got [8, -1, 3])
"""

from __future__ import annotations

import difflib
import json
import re
import types
import typing
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal, Union

import yaml
from pydantic import BaseModel, ValidationError

from sonicspec.errors import SpecError

PathT = tuple[str | int, ...]


@dataclass(frozen=True)
class Problem:
    """One thing wrong (or suspicious) in a spec, with where it is."""

    path: PathT
    message: str
    line: int | None = None
    column: int | None = None
    severity: Literal["error", "warning"] = "error"

    def format(self, source: str) -> str:
        where = source
        if self.line is not None:
            where += f":{self.line}:{self.column or 1}"
        dotted = format_path(self.path)
        label = "warning: " if self.severity == "warning" else ""
        return f"{where}: {label}{dotted + ': ' if dotted else ''}{self.message}"


def format_path(path: Sequence[str | int]) -> str:
    """``('scenes', 1, 'size_m')`` -> ``scenes[1].size_m``."""
    out = ""
    for part in path:
        if isinstance(part, int):
            out += f"[{part}]"
        elif re.fullmatch(r"[A-Za-z_][A-Za-z0-9_]*", part):
            out += f".{part}" if out else part
        else:
            out += f"[{json.dumps(part)}]"
    return out


@dataclass
class SourceMap:
    """Line/column (1-based) of every value and every mapping key in a parsed document."""

    values: dict[PathT, tuple[int, int]] = field(default_factory=dict)
    keys: dict[PathT, tuple[int, int]] = field(default_factory=dict)

    def locate(self, path: PathT, *, key: bool = False) -> tuple[int, int] | None:
        """Location of ``path``'s key (``key=True``) or value, else of its nearest ancestor."""
        if key and path in self.keys:
            return self.keys[path]
        p = tuple(path)
        while True:
            if p in self.values:
                return self.values[p]
            if not p:
                return None
            p = p[:-1]


@dataclass(frozen=True)
class LoadedSpec:
    """A validated spec and where it came from."""

    spec: Any
    source: str
    base_dir: Path
    warnings: tuple[Problem, ...] = ()


MAX_YAML_VALUES = 100_000
"""Most values (scalars, lists, mappings) a document may hold once its aliases are expanded.

Real specs hold a few hundred; a polygon with 1,000 corners about 3,000. The bound stops an
alias bomb ("billion laughs": nine nested aliases, each used nine times, expand to 10^9 values)
while it is parsed, before any Python object is made for it."""

MAX_YAML_DEPTH = 100
"""Most levels of nesting a document may have (real specs have under ten); deeper nesting
would exhaust the parser's recursion instead of failing with a message."""


class _LimitError(yaml.YAMLError):
    """A document over :data:`MAX_YAML_VALUES` or :data:`MAX_YAML_DEPTH`, or a recursive alias."""

    def __init__(self, problem: str, mark: yaml.Mark) -> None:
        super().__init__(problem)
        self.problem = problem
        self.problem_mark = mark


class _BoundedLoader(yaml.SafeLoader):
    """PyYAML's safe loader, counting as it composes what the aliases would expand to.

    The composer makes an alias point to its anchor's node, so composing stays as small as the
    text; building Python values from that graph copies the anchor's values at every use. Each
    node's expanded size (itself and every descendant, aliases counted in full) is remembered
    by identity, so an alias adds its anchor's size in one step: counting costs one pass over
    the text, whatever the aliases would expand to.
    """

    def __init__(self, stream: str) -> None:
        super().__init__(stream)
        self._sizes: dict[int, int] = {}
        self._values = 0
        self._depth = 0
        self._aliased = False

    def _count(self, n: int, mark: yaml.Mark) -> None:
        self._values += n
        if self._values > MAX_YAML_VALUES:
            if self._aliased:
                what = (
                    f"YAML aliases expand to more than {MAX_YAML_VALUES:,} values; each *alias "
                    "repeats everything under its &anchor, so nested aliases grow exponentially "
                    "(write the values out, or use fewer aliases)"
                )
            else:
                what = (
                    f"expected at most {MAX_YAML_VALUES:,} values in a spec, got more; "
                    "real specs hold a few hundred (is this the right file?)"
                )
            raise _LimitError(what, mark)

    def compose_node(self, parent: yaml.Node | None, index: Any) -> yaml.Node:
        event = self.peek_event()
        if isinstance(event, yaml.AliasEvent):
            node = super().compose_node(parent, index)
            size = self._sizes.get(id(node))
            if size is None:
                raise _LimitError(
                    f"alias *{event.anchor} is used inside its own anchor &{event.anchor}; "
                    "expected an alias of a value that is already complete",
                    event.start_mark,
                )
            self._aliased = True
            self._count(size, event.start_mark)
            return node
        self._depth += 1
        if self._depth > MAX_YAML_DEPTH:
            raise _LimitError(
                f"expected at most {MAX_YAML_DEPTH} levels of nesting, got more", event.start_mark
            )
        self._count(1, event.start_mark)
        node = super().compose_node(parent, index)
        self._depth -= 1
        size = 1
        if isinstance(node, yaml.SequenceNode):
            size += sum(self._sizes[id(item)] for item in node.value)
        elif isinstance(node, yaml.MappingNode):
            size += sum(self._sizes[id(k)] + self._sizes[id(v)] for k, v in node.value)
        self._sizes[id(node)] = size
        return node


def _mark(node: yaml.Node) -> tuple[int, int]:
    return node.start_mark.line + 1, node.start_mark.column + 1


def _build(
    loader: yaml.SafeLoader, node: yaml.Node, path: PathT, smap: SourceMap, problems: list[Problem]
) -> Any:
    smap.values[path] = _mark(node)
    if isinstance(node, yaml.MappingNode):
        loader.flatten_mapping(node)
        out: dict[Any, Any] = {}
        for key_node, value_node in node.value:
            key = loader.construct_object(key_node, deep=True)
            if not isinstance(key, (str, int, float, bool)) or isinstance(key, bool):
                line, col = _mark(key_node)
                problems.append(Problem(path, f"keys must be text, got {key!r}", line, col))
                continue
            key = str(key)
            if key in out:
                line, col = _mark(key_node)
                first = smap.keys[(*path, key)]
                problems.append(
                    Problem(
                        (*path, key), f"duplicate key (first given on line {first[0]})", line, col
                    )
                )
                continue
            smap.keys[(*path, key)] = _mark(key_node)
            out[key] = _build(loader, value_node, (*path, key), smap, problems)
        return out
    if isinstance(node, yaml.SequenceNode):
        return [
            _build(loader, item, (*path, i), smap, problems) for i, item in enumerate(node.value)
        ]
    return loader.construct_object(node, deep=True)


def parse_text(text: str, source: str) -> tuple[Any, SourceMap]:
    """Parse YAML (or JSON) text into plain data plus a :class:`SourceMap`.

    Raises :class:`SpecError` for malformed text, an empty document, several documents or
    duplicate keys, each with its own message and location.
    """
    if source.endswith(".json"):
        try:
            json.loads(text)
        except json.JSONDecodeError as exc:
            problem = Problem((), f"malformed JSON: {exc.msg}", exc.lineno, exc.colno)
            raise SpecError(problem.format(source), [problem]) from None
        except RecursionError:
            pass  # nested too deep for the JSON parser: the YAML pass below says where
    loader = _BoundedLoader(text)
    try:
        node = loader.get_single_node()
    except _LimitError as exc:
        mark = exc.problem_mark
        problem = Problem((), exc.problem, mark.line + 1, mark.column + 1)
        raise SpecError(problem.format(source), [problem]) from None
    except yaml.composer.ComposerError as exc:
        line = exc.problem_mark.line + 1 if exc.problem_mark else None
        col = exc.problem_mark.column + 1 if exc.problem_mark else None
        msg = "expected one YAML document, found several (remove the extra '---')"
        if "expected a single document" not in str(exc):
            msg = f"malformed YAML: {exc.problem}"
        problem = Problem((), msg, line, col)
        raise SpecError(problem.format(source), [problem]) from None
    except yaml.MarkedYAMLError as exc:
        mark = exc.problem_mark or exc.context_mark
        line = mark.line + 1 if mark else None
        col = mark.column + 1 if mark else None
        what = exc.problem or str(exc)
        if exc.context:
            what = f"{exc.context}, {what}"
        problem = Problem((), f"malformed YAML: {what}", line, col)
        raise SpecError(problem.format(source), [problem]) from None
    except yaml.YAMLError as exc:
        problem = Problem((), f"malformed YAML: {exc}")
        raise SpecError(problem.format(source), [problem]) from None
    finally:
        loader.dispose()
    if node is None:
        problem = Problem((), "the file is empty; a spec starts with 'sonicspec: 1'", 1, 1)
        raise SpecError(problem.format(source), [problem])
    smap = SourceMap()
    problems: list[Problem] = []
    loader = yaml.SafeLoader("")
    try:
        data = _build(loader, node, (), smap, problems)
    except yaml.YAMLError as exc:
        problem = Problem((), f"malformed YAML: {exc}")
        raise SpecError(problem.format(source), [problem]) from None
    if problems:
        raise SpecError("\n".join(p.format(source) for p in problems), problems)
    if not isinstance(data, dict):
        line, col = smap.values.get((), (1, 1))
        problem = Problem(
            (),
            f"expected a mapping of sections at the top level "
            f"(sonicspec: 1, name: ..., scenes: ...), got {_kind_of(data)}",
            line,
            col,
        )
        raise SpecError(problem.format(source), [problem])
    return data, smap


def _kind_of(value: Any) -> str:
    if value is None:
        return "nothing (null)"
    if isinstance(value, list):
        return "a list"
    if isinstance(value, bool):
        return f"a boolean ({value})"
    if isinstance(value, (int, float)):
        return f"a number ({value})"
    if isinstance(value, str):
        return f"text ({value!r})"
    return type(value).__name__


# --- mapping pydantic error locations back to the document ---------------------------------


def _unwrap(tp: Any) -> Any:
    while True:
        origin = typing.get_origin(tp)
        if origin is typing.Annotated:
            tp = typing.get_args(tp)[0]
            continue
        if origin in (Union, types.UnionType):
            args = [a for a in typing.get_args(tp) if a is not type(None)]
            if len(args) == 1:
                tp = args[0]
                continue
        return tp


def _union_members(tp: Any) -> list[Any]:
    tp = _unwrap(tp)
    if typing.get_origin(tp) in (Union, types.UnionType):
        out = []
        for a in typing.get_args(tp):
            if a is type(None):
                continue
            out.extend(_union_members(a))
        return out
    return [tp]


def _tag_of(model: Any) -> tuple[str, ...]:
    if isinstance(model, type) and issubclass(model, BaseModel) and "kind" in model.model_fields:
        ann = _unwrap(model.model_fields["kind"].annotation)
        if typing.get_origin(ann) is Literal:
            return tuple(str(a) for a in typing.get_args(ann))
    return ()


def kinds_at(tp: Any) -> list[str]:
    """The ``kind`` values a (possibly nested) discriminated union accepts."""
    return [t for m in _union_members(tp) for t in _tag_of(m)]


def walk_location(
    root: type[BaseModel],
    loc: Sequence[str | int],
    data: Any,
    branches: list[tuple[tuple, str]] | None = None,
) -> tuple[PathT, Any]:
    """Translate a pydantic error ``loc`` into a path in the document.

    Returns the document path (with union tags dropped) and the type found at the end of
    ``loc``, which lets messages list the allowed fields or kinds. Plain-union member names
    that pydantic puts into ``loc`` are appended to ``branches`` as (loc prefix, member).
    """
    tp: Any = root
    cur = data
    path: list[str | int] = []
    for elem in loc:
        tp_u = _unwrap(tp)
        members = _union_members(tp)
        if len(members) > 1:
            # A discriminated union puts the tag value into loc; step into that member.
            chosen = [m for m in members if str(elem) in _tag_of(m)]
            if chosen:
                tp = chosen[0]
                continue
            # A plain union (e.g. list | 'auto'): pydantic names the member; skip the name.
            if isinstance(elem, str) and not (isinstance(cur, dict) and elem in cur):
                if branches is not None:
                    branches.append((tuple(loc[: loc.index(elem)]), elem))
                continue
            tp_u = next(
                (m for m in members if isinstance(m, type) and issubclass(m, BaseModel)), tp_u
            )
        if isinstance(elem, str) and elem.startswith(("function-", "[key]")):
            continue
        path.append(elem)
        if isinstance(cur, dict):
            cur = cur.get(elem)
        elif isinstance(cur, list) and isinstance(elem, int) and 0 <= elem < len(cur):
            cur = cur[elem]
        else:
            cur = None
        if isinstance(tp_u, type) and issubclass(tp_u, BaseModel):
            f = tp_u.model_fields.get(str(elem))
            tp = f.annotation if f is not None else None
        else:
            origin = typing.get_origin(tp_u)
            args = typing.get_args(tp_u)
            if origin in (list, Sequence) and args:
                tp = args[0]
            elif origin is tuple and args:
                tp = (
                    args[0]
                    if len(args) == 2 and args[1] is Ellipsis
                    else (args[elem] if isinstance(elem, int) and elem < len(args) else None)
                )
            elif origin in (dict, Mapping) and len(args) == 2:
                tp = args[1]
            else:
                tp = None
    return tuple(path), tp


def _model_at(root: type[BaseModel], loc: Sequence[str | int], data: Any) -> type[BaseModel] | None:
    _, tp = walk_location(root, loc, data)
    members = [m for m in _union_members(tp) if isinstance(m, type) and issubclass(m, BaseModel)]
    if len(members) == 1:
        return members[0]
    return None


def did_you_mean(word: str, options: Sequence[str]) -> str:
    """``"; did you mean 'x'?"`` for the closest option, or an empty string."""
    match = difflib.get_close_matches(str(word), [str(o) for o in options], n=1, cutoff=0.6)
    if not match:
        lowered = {str(o).lower(): str(o) for o in options}
        if str(word).lower() in lowered:
            match = [lowered[str(word).lower()]]
    return f"; did you mean {match[0]!r}?" if match else ""


def _show(value: Any) -> str:
    if isinstance(value, (list, tuple)):
        from sonicspec.spec.base import _fmt

        return _fmt(value)
    if isinstance(value, dict):
        return "a mapping"
    if isinstance(value, float) and value.is_integer():
        return str(int(value))
    return repr(value) if isinstance(value, str) else str(value)


def problems_from_validation(
    exc: ValidationError, root: type[BaseModel], data: Any, smap: SourceMap
) -> list[Problem]:
    """One :class:`Problem` per pydantic error, located in the document."""
    problems: list[Problem] = []
    seen: set[tuple[PathT, str]] = set()
    for err in _best_union_branches(exc.errors(include_url=False), root, data):
        loc = err["loc"]
        kind = err["type"]
        ctx = err.get("ctx") or {}
        path, _ = walk_location(root, loc, data)
        if kind == "missing":
            parent = _model_at(root, loc[:-1], data)
            message = "required field missing"
            if parent is not None and loc and loc[-1] == "kind":
                message += f"; one of {', '.join(map(repr, kinds_at_parent(root, loc, data)))}"
            where = smap.locate(path[:-1])
        elif kind == "extra_forbidden":
            parent = _model_at(root, loc[:-1], data)
            allowed = sorted(parent.model_fields) if parent is not None else []
            message = f"unknown field {str(path[-1])!r}" + did_you_mean(str(path[-1]), allowed)
            if not did_you_mean(str(path[-1]), allowed) and allowed:
                message += f" (allowed: {', '.join(allowed)})"
            where = smap.locate(path, key=True)
        elif kind == "union_tag_invalid":
            tags = re.findall(r"'([^']*)'", str(ctx.get("expected_tags", "")))
            got = ctx.get("tag")
            path = (*path, "kind")
            message = (
                f"unknown kind {got!r}; expected one of {', '.join(map(repr, tags))}"
                + did_you_mean(str(got), tags)
            )
            where = smap.locate(path)
        elif kind == "union_tag_not_found":
            tags = kinds_at_parent(root, (*loc, "kind"), data)
            message = f"'kind' is required; expected one of {', '.join(map(repr, tags))}"
            where = smap.locate(path)
        elif kind == "literal_error":
            options = re.findall(r"'([^']*)'|(\d+)", str(ctx.get("expected", "")))
            flat = [a or b for a, b in options]
            message = (
                f"expected {ctx.get('expected')}, got {_show(err.get('input'))}"
                + did_you_mean(str(err.get("input")), flat)
            )
            where = smap.locate(path)
        elif kind in ("model_type", "model_attributes_type", "dict_type"):
            message = f"expected a mapping of fields, got {_kind_of(err.get('input'))}"
            where = smap.locate(path)
        else:
            msg = err["msg"]
            if msg.startswith("Value error, "):
                msg = msg[len("Value error, ") :]
            if msg.startswith("Input should be "):
                msg = "must be " + msg[len("Input should be ") :]
            elif msg.startswith("String should "):
                msg = "text must " + msg[len("String should ") :]
            elif msg.startswith("List should "):
                msg = "list must " + msg[len("List should ") :]
            elif msg.startswith("Dictionary should "):
                msg = "mapping must " + msg[len("Dictionary should ") :]
            if "(got " not in msg:
                msg = f"{msg} (got {_show(err.get('input'))})"
            message = msg
            where = smap.locate(path)
        if (path, message) in seen:
            continue
        seen.add((path, message))
        line, col = where if where else (None, None)
        problems.append(Problem(path, message, line, col))
    return problems


def _best_union_branches(errors: list[dict], root: type[BaseModel], data: Any) -> list[dict]:
    """For a plain union (e.g. ``list[int] | 'auto'``) keep only the member that got furthest.

    Pydantic reports one error per member; the member whose errors reach deepest into the
    value is the one the user meant, like jsonschema's ``best_match``.
    """
    depth: dict[tuple, int] = {}
    tagged = []
    for err in errors:
        branches: list[tuple[tuple, str]] = []
        walk_location(root, err["loc"], data, branches)
        tagged.append((err, branches))
        for prefix, _ in branches:
            depth[prefix] = max(depth.get(prefix, 0), len(err["loc"]))
    return [
        err
        for err, branches in tagged
        if all(len(err["loc"]) == depth[prefix] for prefix, _ in branches)
    ]


def kinds_at_parent(root: type[BaseModel], loc: Sequence[str | int], data: Any) -> list[str]:
    """Kinds accepted by the union that owns the ``kind`` field at ``loc``."""
    _, tp = walk_location(root, loc[:-1], data)
    return kinds_at(tp) if tp is not None else []


def sort_problems(problems: Sequence[Problem]) -> list[Problem]:
    """File order: by line, then column; unlocated problems last."""
    return sorted(problems, key=lambda p: (p.line is None, p.line or 0, p.column or 0))
