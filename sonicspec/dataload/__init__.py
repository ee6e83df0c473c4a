"""Using a built dataset: a map-style loader with dynamic mixing (:mod:`.loader`), the paper's
evaluation (:mod:`.evaluate`) and Hugging Face / WebDataset exports (:mod:`.hub`).

Named ``dataload`` because ``sonicspec/data/`` holds the package's data files (materials,
mpcat40, the schema copy).
"""

from sonicspec.dataload.folder import DatasetError, DatasetFolder, Group
from sonicspec.dataload.loader import PRESETS, MixingConfig, SonicspecDataset, preset

__all__ = ["PRESETS", "DatasetError", "DatasetFolder", "Group", "MixingConfig",
           "SonicspecDataset", "preset"]
