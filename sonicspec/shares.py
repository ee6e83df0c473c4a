"""Corpus split shares: the one rule the spec checks and the corpus readers both apply.

FSD50K, FMA and plain-folder corpora are cut into splits by share. What a share list means is
decided here, once, in plain Python (the spec package imports it and must not need numpy):
only the spec's own splits take part, their shares must sum to 1, and a corpus that gives no
shares gets SonicSet's 7:2:1 (train:val:test) renormalised over the splits the spec has, so
a spec with only train and test splits takes 0.875 and 0.125 of the corpus.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence

from sonicspec.errors import SonicspecError

SONICSET_SHARES: Mapping[str, float] = {"train": 0.7, "val": 0.2, "test": 0.1}
"""SonicSet's corpus split (7:2:1), the default weights of the splits with these names."""

SUM_TOLERANCE = 1e-6


def _yaml_shares(splits: Sequence[str], weights: Sequence[float]) -> str:
    """``{train: 0.875, test: 0.125}``: ``weights`` scaled to sum to 1, four decimals, the
    largest share taking the rounding so the written shares sum to 1 exactly."""
    total = math.fsum(weights)
    shares = [w / total if total > 0 else 1 / len(splits) for w in weights]
    rounded = [round(s, 4) for s in shares]
    big = max(range(len(rounded)), key=lambda i: rounded[i])
    rounded[big] = round(1 - math.fsum(r for i, r in enumerate(rounded) if i != big), 4)
    return "{" + ", ".join(f"{n}: {r:g}" for n, r in zip(splits, rounded, strict=True)) + "}"


def split_shares(ratios: Mapping[str, float] | None, splits: Sequence[str]) -> dict[str, float]:
    """The share of a corpus each split gets, by split name (sorted; zero shares dropped).

    Parameters
    ----------
    ratios
        Share by split name as the user wrote it; shares of names outside ``splits`` are
        ignored. None: SonicSet's 7:2:1 (:data:`SONICSET_SHARES`) renormalised over
        ``splits``.
    splits
        The splits the corpus feeds (the spec's splits).

    Raises
    ------
    SonicspecError
        The message reads ``expected <allowed>, got <value>; hint`` without a location (the
        caller knows where the shares were written and prefixes it).
    """
    splits = list(dict.fromkeys(splits))
    if not splits:
        raise SonicspecError("expected at least one split with a share, got none")
    if ratios is None:
        unknown = [s for s in splits if s not in SONICSET_SHARES]
        if unknown:
            raise SonicspecError(
                f"expected split names with a default share ({', '.join(SONICSET_SHARES)}), "
                f"got {', '.join(repr(s) for s in unknown)}; give the shares, e.g. "
                f"split_ratios: {_yaml_shares(splits, [1.0] * len(splits))}")
        total = math.fsum(SONICSET_SHARES[s] for s in splits)
        return {s: SONICSET_SHARES[s] / total for s in sorted(splits)}
    missing = [s for s in splits if s not in ratios]
    if missing:
        raise SonicspecError(
            f"expected a share for every split ({', '.join(splits)}), got none for "
            f"{', '.join(repr(s) for s in missing)}")
    used = {s: ratios[s] for s in splits}
    for name, share in used.items():
        if not math.isfinite(share) or share < 0:
            raise SonicspecError(f"expected shares >= 0, got {name}: {share}")
    total = math.fsum(used.values())
    if abs(total - 1.0) > SUM_TOLERANCE:
        ignored = [s for s in ratios if s not in used]
        over = f" over the splits {', '.join(splits)}" if ignored else ""
        hint = f"; write split_ratios: {_yaml_shares(splits, list(used.values()))}"
        if all(s in SONICSET_SHARES for s in splits):
            hint += ", or leave split_ratios out for SonicSet's 7:2:1 over these splits"
        raise SonicspecError(f"expected shares summing to 1{over}, got {total:g}{hint}")
    return {name: float(share) for name, share in sorted(used.items()) if share > 0}
