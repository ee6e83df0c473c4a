"""The spec language: versioned, validated descriptions of a whole dataset."""

from sonicspec.spec.dataset import SPEC_VERSION, DatasetSpec
from sonicspec.spec.load import LoadedSpec, Problem
from sonicspec.spec.validate import load_spec, validate_file, validate_text

__all__ = [
    "SPEC_VERSION",
    "DatasetSpec",
    "LoadedSpec",
    "Problem",
    "load_spec",
    "validate_file",
    "validate_text",
]
