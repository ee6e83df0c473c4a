"""Building blocks of the spec language: the model base class and reusable field types.

Every reusable type here validates in pydantic *and* describes itself exactly in the JSON
Schema, so an editor checking a file against ``schema/`` and ``sonicspec validate`` agree on
what is a type error. Cross-field rules (ranges ordered, names known) that JSON Schema cannot
express raise pydantic custom errors with messages meant for people.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Annotated, Any

from pydantic import AfterValidator, BaseModel, BeforeValidator, ConfigDict, Field, WithJsonSchema
from pydantic_core import PydanticCustomError

from sonicspec.units import OCTAVE_BANDS_HZ


class SpecModel(BaseModel):
    """Base of every spec model: immutable, strict about unknown keys, validates defaults."""

    model_config = ConfigDict(
        frozen=True,
        extra="forbid",
        validate_default=True,
        allow_inf_nan=False,
    )


def _fmt(values: Sequence[Any]) -> str:
    """Render numbers the way a user typed them: 8 rather than 8.0."""
    parts = []
    for v in values:
        if isinstance(v, float) and v.is_integer():
            parts.append(str(int(v)))
        else:
            parts.append(repr(v) if isinstance(v, str) else str(v))
    return "[" + ", ".join(parts) + "]"


def _number_schema(gt: float | None, ge: float | None, le: float | None, integer: bool) -> dict:
    schema: dict[str, Any] = {"type": "integer" if integer else "number"}
    if gt is not None:
        schema["exclusiveMinimum"] = gt
    if ge is not None:
        schema["minimum"] = ge
    if le is not None:
        schema["maximum"] = le
    return schema


def _bound_text(gt: float | None, ge: float | None, le: float | None) -> str:
    parts = []
    if gt is not None:
        parts.append(f"> {gt:g}")
    if ge is not None:
        parts.append(f">= {ge:g}")
    if le is not None:
        parts.append(f"<= {le:g}")
    return " and ".join(parts)


def _within(v: float, gt: float | None, ge: float | None, le: float | None) -> bool:
    return (gt is None or v > gt) and (ge is None or v >= ge) and (le is None or v <= le)


def _length_check(n: int, shape: str | None = None) -> Any:
    """Before-validator: a list of the wrong length gets one clear message, not one per item."""
    if shape is None:
        shape = "[" + ", ".join("xyz"[:n]) + "]" if n <= 3 else ""

    def check(v: Any) -> Any:
        if isinstance(v, (list, tuple)) and len(v) != n:
            raise PydanticCustomError(
                "vector_length",
                "expected {n} values {shape} (got {k}: {got})",
                {"n": n, "shape": shape, "k": len(v), "got": _fmt(v)},
            )
        return v

    return check


def vector(
    n: int,
    *,
    gt: float | None = None,
    ge: float | None = None,
    le: float | None = None,
) -> Any:
    """A fixed-length list of finite numbers, optionally bounded, e.g. a position or a size."""
    item = _number_schema(gt, ge, le, integer=False)

    def check(v: tuple[float, ...]) -> tuple[float, ...]:
        if not all(_within(x, gt, ge, le) for x in v):
            raise PydanticCustomError(
                "vector_bounds",
                "all values must be {bound} (got {got})",
                {"bound": _bound_text(gt, ge, le), "got": _fmt(v)},
            )
        return v

    return Annotated[
        tuple[(float,) * n],  # type: ignore[misc]
        BeforeValidator(_length_check(n)),
        AfterValidator(check),
        WithJsonSchema(
            {
                "type": "array",
                "prefixItems": [item] * n,
                "items": False,
                "minItems": n,
                "maxItems": n,
            }
        ),
    ]


def value_range(
    *,
    ge: float | None = None,
    gt: float | None = None,
    le: float | None = None,
    integer: bool = False,
) -> Any:
    """A ``[min, max]`` pair with ``min <= max``; both ends inclusive.

    Ranges are drawn uniformly by the sampler; ``[x, x]`` fixes the value.
    """
    item = _number_schema(gt, ge, le, integer=integer)
    py_type = int if integer else float
    bound = _bound_text(gt, ge, le)
    expected = "a range [min, max]" + (f" with both ends {bound}" if bound else "")

    def shape(v: Any) -> Any:
        """A single number or text is not a range: say what one looks like."""
        if not isinstance(v, (list, tuple)):
            raise PydanticCustomError(
                "range_type",
                "expected {expected}; [x, x] fixes the value (got {got})",
                {"expected": expected,
                 "got": repr(v) if isinstance(v, str) else _fmt([v])[1:-1]},
            )
        return _length_check(2, "[min, max]")(v)

    def check(v: tuple[float, float]) -> tuple[float, float]:
        if not all(_within(x, gt, ge, le) for x in v):
            raise PydanticCustomError(
                "range_bounds",
                "both ends must be {bound} (got {got})",
                {"bound": _bound_text(gt, ge, le), "got": _fmt(v)},
            )
        if v[0] > v[1]:
            raise PydanticCustomError(
                "range_order",
                "expected [min, max] with min <= max (got {got})",
                {"got": _fmt(v)},
            )
        return v

    return Annotated[
        tuple[py_type, py_type],
        BeforeValidator(shape),
        AfterValidator(check),
        WithJsonSchema(
            {
                "type": "array",
                "prefixItems": [item, item],
                "items": False,
                "minItems": 2,
                "maxItems": 2,
            }
        ),
    ]


N_BANDS = len(OCTAVE_BANDS_HZ)
_BANDS_TEXT = "125, 250, 500, 1000, 2000, 4000, 8000 Hz"


def _broadcast_bands(v: Any) -> Any:
    if isinstance(v, bool):
        return v
    if isinstance(v, (int, float)):
        return (float(v),) * N_BANDS
    return v


def _check_bands(v: tuple[float, ...]) -> tuple[float, ...]:
    if len(v) != N_BANDS:
        raise PydanticCustomError(
            "band_count",
            "expected one value or {n} values for the octave bands {bands}, got {got} values",
            {"n": N_BANDS, "bands": _BANDS_TEXT, "got": len(v)},
        )
    if not all(0.0 <= x <= 1.0 for x in v):
        raise PydanticCustomError(
            "coefficient_range",
            "every coefficient must lie in [0, 1] (got {got})",
            {"got": _fmt(v)},
        )
    return v


BandCoefficients = Annotated[
    tuple[float, ...],
    BeforeValidator(_broadcast_bands),
    AfterValidator(_check_bands),
    WithJsonSchema(
        {
            "anyOf": [
                {"type": "number", "minimum": 0, "maximum": 1},
                {
                    "type": "array",
                    "items": {"type": "number", "minimum": 0, "maximum": 1},
                    "minItems": N_BANDS,
                    "maxItems": N_BANDS,
                },
            ]
        }
    ),
]
"""Per-octave-band coefficients (125 Hz–8 kHz): one number for every band, or seven."""


IDENTIFIER_PATTERN = r"^[A-Za-z0-9][A-Za-z0-9_.\-]*$"
Identifier = Annotated[str, Field(pattern=IDENTIFIER_PATTERN, min_length=1, max_length=128)]
"""Names that become folder names and job labels: letters, digits, ``_ . -``."""

SplitName = Annotated[str, Field(pattern=r"^[A-Za-z][A-Za-z0-9_\-]*$", max_length=64)]
