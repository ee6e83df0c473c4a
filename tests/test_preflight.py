"""`validate` finds what a build would find: split shares, missing packages and tools, meshes
and corpora that cannot be read (issue 16, part 3)."""

from __future__ import annotations

import pytest
from spec_cases import BASE

from sonicspec.errors import CorpusError, SonicspecError
from sonicspec.shares import split_shares
from sonicspec.spec import validate_text
from sonicspec.spec.load import format_path
from sonicspec.stages.corpus import corpus_shares

# --- split shares: one rule for validate and the corpus stage ----------------------------


def test_default_shares_follow_the_spec_splits() -> None:
    """Issue 16: the 7:2:1 default with only train and test splits failed 52 s into a build."""
    assert split_shares(None, ["train", "test"]) == pytest.approx({"train": 0.875, "test": 0.125})
    assert split_shares(None, ["train", "val", "test"]) == pytest.approx(
        {"train": 0.7, "val": 0.2, "test": 0.1})
    assert split_shares(None, ["train"]) == {"train": 1.0}


def test_default_shares_need_known_split_names() -> None:
    with pytest.raises(SonicspecError, match=r"expected split names with a default share "
                       r"\(train, val, test\), got 'dev'; give the shares, e.g. split_ratios: "
                       r"\{train: 0.5, dev: 0.5\}"):
        split_shares(None, ["train", "dev"])


def test_shares_of_other_splits_are_ignored_and_the_rest_must_sum_to_one() -> None:
    assert split_shares({"train": 0.8, "test": 0.2, "val": 0.5}, ["train", "test"]) == {
        "test": 0.2, "train": 0.8}
    with pytest.raises(SonicspecError, match=r"expected shares summing to 1 over the splits "
                       r"train, test, got 0.8; write split_ratios: \{train: 0.875, test: 0.125\}"
                       r", or leave split_ratios out"):
        split_shares({"train": 0.7, "val": 0.2, "test": 0.1}, ["train", "test"])
    with pytest.raises(SonicspecError, match=r"expected a share for every split \(train, "
                       r"test\), got none for 'test'"):
        split_shares({"train": 1.0}, ["train", "test"])
    with pytest.raises(SonicspecError, match=r"expected shares >= 0, got test: -0.5"):
        split_shares({"train": 1.5, "test": -0.5}, ["train", "test"])
    with pytest.raises(SonicspecError, match=r"expected at least one split"):
        split_shares({"train": 1.0}, [])


def test_suggested_shares_sum_to_one() -> None:
    with pytest.raises(SonicspecError, match=r"\{a: 0.3334, b: 0.3333, c: 0.3333\}") as exc:
        split_shares({"a": 0.2, "b": 0.2, "c": 0.2}, ["a", "b", "c"])
    written = str(exc.value).split("{")[1].split("}")[0]
    assert sum(float(x.split(": ")[1]) for x in written.split(", ")) == pytest.approx(1, abs=1e-9)


def test_corpus_stage_names_the_field() -> None:
    with pytest.raises(CorpusError, match=r"corpora.noise.split_ratios: expected shares summing "
                       r"to 1 over the splits train, test, got 0.8"):
        corpus_shares({"train": 0.7, "val": 0.2, "test": 0.1}, ["train", "test"], "noise")


NOISE = "  noise: {kind: fsd50k, root: data/fsd, split_ratios: {train: 0.8, test: 0.2}}"


def _errors(text: str) -> list[tuple[str, int | None, str, str]]:
    _, problems = validate_text(text, "s.yaml")
    return [(format_path(p.path), p.line, p.severity, p.message) for p in problems]


def test_validate_accepts_default_shares_with_train_and_test_only() -> None:
    assert NOISE in BASE
    loaded, problems = validate_text(BASE.replace(NOISE, "  noise: {kind: fsd50k, root: "
                                                         "data/fsd}"), "s.yaml")
    assert loaded is not None, problems


def test_validate_rejects_what_the_corpus_stage_rejects() -> None:
    """The user's 0.7/0.2/0.1 with train and test splits: validate said yes, the build no."""
    text = BASE.replace("{train: 0.8, test: 0.2}", "{train: 0.7, val: 0.2, test: 0.1}")
    found = _errors(text)
    assert ("corpora.noise.split_ratios", 35, "error",
            "expected shares summing to 1 over the splits train, test, got 0.8; write "
            "split_ratios: {train: 0.875, test: 0.125}, or leave split_ratios out for "
            "SonicSet's 7:2:1 over these splits") in found
    assert ("corpora.noise.split_ratios.val", 35, "warning",
            "expected shares of the spec's splits (train, test), got one for 'val', which is "
            "not used") in found


def test_unused_share_warns_with_did_you_mean() -> None:
    text = BASE.replace("{train: 0.8, test: 0.2}", "{train: 0.8, tset: 0.2}")
    found = _errors(text)
    assert ("corpora.noise.split_ratios", 35, "error",
            "expected a share for every split (train, test), got none for 'test'") in found
    assert any(f[0] == "corpora.noise.split_ratios.tset" and f[2] == "warning"
               and f[3].endswith("did you mean 'test'?") for f in found), found
