"""JSON Schema export: deterministic, documented, for editors and for ``jsonschema`` checks."""

from __future__ import annotations

import json
from typing import Any

from sonicspec.spec.dataset import SPEC_VERSION, DatasetSpec

SCHEMA_FILENAME = f"sonicspec-v{SPEC_VERSION}.schema.json"
SCHEMA_ID = f"https://sonicspec.dev/schema/{SCHEMA_FILENAME}"


def _constrain_keys(node: Any) -> None:
    """Turn pydantic's ``patternProperties`` for constrained dict keys into ``propertyNames``.

    ``patternProperties`` alone lets keys that do not match through unchecked; pydantic
    rejects them, so the schema must too.
    """
    if isinstance(node, dict):
        patterns = node.get("patternProperties")
        if isinstance(patterns, dict) and len(patterns) == 1 and "properties" not in node:
            ((pattern, value),) = patterns.items()
            del node["patternProperties"]
            node["additionalProperties"] = value
            node.setdefault("propertyNames", {})["pattern"] = pattern
        for value in node.values():
            _constrain_keys(value)
    elif isinstance(node, list):
        for value in node:
            _constrain_keys(value)


def json_schema() -> dict[str, Any]:
    """The JSON Schema (draft 2020-12) of the current spec version."""
    schema = DatasetSpec.model_json_schema(mode="validation")
    _constrain_keys(schema)
    schema["$schema"] = "https://json-schema.org/draft/2020-12/schema"
    schema["$id"] = SCHEMA_ID
    schema["title"] = f"sonicspec dataset spec, version {SPEC_VERSION}"
    return schema


def schema_text() -> str:
    """The schema as stable text: sorted keys, two-space indent, final newline."""
    return json.dumps(json_schema(), indent=2, sort_keys=True, ensure_ascii=False) + "\n"
