"""sonicspec: realistic moving-source speech datasets from a versioned spec."""

__version__ = "0.1.0.dev0"
