"""The command line on good and bad specs: exit codes, messages, never a traceback."""

from __future__ import annotations

import json
import re
import resource
import subprocess
import sys
from pathlib import Path

import pytest
import yaml
from spec_cases import BASE

from sonicspec.cli import main
from sonicspec.spec import validate_file
from sonicspec.spec.templates import PRESETS
from sonicspec.spec.validate import MAX_SPEC_BYTES

ROOT = Path(__file__).resolve().parents[1]


def run_cli(*args: str, cwd: Path | None = None) -> subprocess.CompletedProcess:
    """Run the real console entry point in a child process (what a user sees)."""
    return subprocess.run([sys.executable, "-m", "sonicspec.cli", *args], capture_output=True,
                          text=True, cwd=cwd, timeout=120)


def write(tmp_path: Path, name: str, text: str | bytes) -> Path:
    path = tmp_path / name
    if isinstance(text, bytes):
        path.write_bytes(text)
    else:
        path.write_text(text)
    return path


def test_valid_examples_exit_zero() -> None:
    result = run_cli("validate", *[str(p) for p in sorted((ROOT / "specs").glob("*.yaml"))])
    assert result.returncode == 0, result.stderr
    assert result.stdout.count(": valid (") == len(list((ROOT / "specs").glob("*.yaml")))


@pytest.mark.parametrize(
    ("name", "text", "expected"),
    [
        ("malformed.yaml", "sonicspec: 1\nname: [unclosed\n", "malformed YAML"),
        ("tabs.yaml", "sonicspec: 1\nname:\n\t- x\n", "malformed YAML"),
        ("empty.yaml", "", "the file is empty"),
        ("comments.yaml", "# only a comment\n", "the file is empty"),
        ("list.yaml", "- sonicspec: 1\n", "expected a mapping of sections at the top level"),
        ("scalar.yaml", "hello\n", "expected a mapping of sections at the top level"),
        ("version.yaml", "sonicspec: 7\nname: x\n", "spec version 7 is newer"),
        ("version0.yaml", "sonicspec: 0\nname: x\n", "unknown spec version 0"),
        ("noversion.yaml", "name: x\n", "put 'sonicspec: 1' at the top"),
        ("twodocs.yaml", "sonicspec: 1\n---\nsonicspec: 1\n", "found several"),
        ("dupkey.yaml", "sonicspec: 1\nname: a\nname: b\n", "duplicate key (first given on line 2"),
        ("badjson.json", '{"sonicspec": 1,,}', "malformed JSON"),
        ("latin1.yaml", b"sonicspec: 1\nname: caf\xe9\n", "not UTF-8"),
    ],
)
def test_broken_files_get_their_own_message_and_exit_2(tmp_path: Path, name: str, text: str,
                                                        expected: str) -> None:
    path = write(tmp_path, name, text)
    result = run_cli("validate", str(path))
    assert result.returncode == 2, result
    assert expected in result.stderr, result.stderr
    assert "Traceback" not in result.stderr + result.stdout
    assert result.stderr.startswith(str(path)), result.stderr


def _limit_memory_to_1_gb() -> None:
    resource.setrlimit(resource.RLIMIT_AS, (1 << 30, 1 << 30))


def test_alias_bomb_exits_2_in_bounded_memory(tmp_path: Path) -> None:
    # Issue 16: 9 levels x 9 aliases ("billion laughs") took 12.9 GB before it was killed.
    lines = ["sonicspec: 1", "a0: &a0 [" + ", ".join(["lol"] * 9) + "]"]
    lines += [f"a{i}: &a{i} [" + ", ".join([f"*a{i - 1}"] * 9) + "]" for i in range(1, 10)]
    path = write(tmp_path, "bomb.yaml", "\n".join([*lines, "name: *a9", ""]))
    result = subprocess.run([sys.executable, "-m", "sonicspec.cli", "validate", str(path)],
                            capture_output=True, text=True, timeout=120,
                            preexec_fn=_limit_memory_to_1_gb)
    assert result.returncode == 2, result.stderr
    assert f"{path}:7:10: YAML aliases expand to more than 100,000 values" in result.stderr
    assert "Traceback" not in result.stderr and "MemoryError" not in result.stderr


def test_too_big_file_is_refused_before_it_is_read(tmp_path: Path) -> None:
    path = tmp_path / "huge.yaml"
    with path.open("wb") as fh:  # sparse: 8 GiB of nothing, refused by its size alone
        fh.truncate(8 << 30)
    loaded, problems = validate_file(path)
    assert loaded is None
    assert [p.format(str(path)) for p in problems] == [
        f"{path}: expected a spec file of at most 4.0 MiB (4,194,304 bytes), got 8192.0 MiB "
        "(8,589,934,592 bytes); real specs are a few KB; is this the right file?"
    ]
    small = write(tmp_path, "limit.yaml", "# " + "x" * (MAX_SPEC_BYTES - 3) + "\n")
    assert "the file is empty" in validate_file(small)[1][0].message  # at the bound: read
    result = run_cli("validate", str(path))
    assert result.returncode == 2 and "expected a spec file of at most 4.0 MiB" in result.stderr


def test_missing_file_exits_2(tmp_path: Path) -> None:
    result = run_cli("validate", str(tmp_path / "nope.yaml"))
    assert result.returncode == 2 and "no such file" in result.stderr


def test_five_errors_printed_with_locations(tmp_path: Path) -> None:
    text = (BASE.replace("seed: 1", "seed: -1")
            .replace("size_m: [6, 5, 3]", "size_m: [6, 0, 3]")
            .replace("  n: 4", "  n: 1")
            .replace("rays: 5000", "rays: 1")
            .replace("audio_format: flac", "audio_format: ogg"))
    path = write(tmp_path, "five.yaml", text)
    result = run_cli("validate", str(path))
    assert result.returncode == 2
    lines = result.stderr.strip().splitlines()
    assert lines[-1] == f"{path}: invalid (5 errors)"
    for fragment in (":3:7: seed:", ":8:13: scenes[0].size_m:", ":22:6: microphone.n:",
                     ":31:9: acoustics.rays:", ":47:17: outputs.audio_format:"):
        assert any(fragment in line for line in lines), (fragment, lines)


def test_json_output(tmp_path: Path) -> None:
    path = write(tmp_path, "bad.yaml", BASE.replace("seed: 1", "seed: -1"))
    result = run_cli("validate", "--json", str(path))
    assert result.returncode == 2
    (report,) = json.loads(result.stdout)
    assert report["valid"] is False
    assert report["problems"][0]["path"] == ["seed"] and report["problems"][0]["line"] == 3


def test_check_files_reports_missing_corpus_and_mesh(tmp_path: Path) -> None:
    spec = (ROOT / "specs" / "sonicset.yaml").read_text()
    path = write(tmp_path, "s.yaml", spec)
    assert run_cli("validate", str(path)).returncode == 0
    result = run_cli("validate", "--check-files", str(path))
    assert result.returncode == 2
    assert "scenes[0].path: glob 'data/mp3d/*/*.glb' matches no file" in result.stderr
    assert "corpora.speech.root: corpus folder" in result.stderr
    # Make the folders exist: the LibriSpeech subsets are then checked one by one.
    (tmp_path / "data/mp3d/abc").mkdir(parents=True)
    (tmp_path / "data/mp3d/abc/abc.glb").write_bytes(b"")
    for sub in ("train-clean-360", "dev-clean"):
        (tmp_path / "data/LibriSpeech" / sub).mkdir(parents=True)
    result = run_cli("validate", "--check-files", str(path))
    assert "glob" not in result.stderr
    assert "test-clean' does not exist" in result.stderr


def test_warnings_do_not_fail(tmp_path: Path) -> None:
    path = write(tmp_path, "w.yaml", BASE.replace("rays: 5000", "rays: 500"))
    result = run_cli("validate", str(path))
    assert result.returncode == 0, result.stderr
    assert "warning: acoustics.rays" in result.stderr


@pytest.mark.parametrize("preset", PRESETS)
def test_init_writes_specs_that_validate(tmp_path: Path, preset: str) -> None:
    out = tmp_path / "sub" / f"{preset}.yaml"
    assert main(["init", "--preset", preset, "-o", str(out)]) == 0
    loaded, problems = validate_file(out)
    assert loaded is not None, [p.format(str(out)) for p in problems]
    first = out.read_text().splitlines()[0]
    assert first.startswith("# yaml-language-server: $schema=")
    schema_ref = first.split("$schema=")[1]
    assert json.loads((out.parent / schema_ref).read_text())["title"].startswith("sonicspec")


def test_init_refuses_to_overwrite(tmp_path: Path) -> None:
    out = write(tmp_path, "keep.yaml", "precious\n")
    assert main(["init", "-o", str(out)]) == 1
    assert out.read_text() == "precious\n"
    assert main(["init", "-o", str(out), "--force"]) == 0


def test_schema_command_prints_the_checked_in_schema() -> None:
    result = run_cli("schema")
    assert result.returncode == 0
    assert result.stdout == (ROOT / "schema" / "sonicspec-v1.schema.json").read_text()


def test_plan_summary_of_the_demo() -> None:
    result = run_cli("plan", "--summary", str(ROOT / "specs" / "demo.yaml"))
    assert result.returncode == 0, result.stderr
    assert "dataset demo: 6 groups" in result.stdout
    result = run_cli("plan", "--summary", "--json", str(ROOT / "specs" / "demo.yaml"))
    summary = json.loads(result.stdout)
    assert summary["groups"] == 6
    assert [s["name"] for s in summary["splits"]] == ["train", "val", "test"]


def test_plan_summary_says_the_microphone_moves(tmp_path: Path) -> None:
    # A 1.5 m walk at 0.25 m spacing: 7 microphone points added to each source's estimate.
    text = (ROOT / "specs" / "demo.yaml").read_text().replace(
        "  kind: mono\n  height_m: 1.5",
        "  kind: mono\n  height_m: 1.5\n  trajectory: {kind: line, start_m: [3.5, 2.0, 1.5], "
        "end_m: [5.0, 2.0, 1.5], facing: fixed}")
    spec = write(tmp_path, "demo.yaml", text)
    still = run_cli("plan", "--summary", str(ROOT / "specs" / "demo.yaml")).stdout
    result = run_cli("plan", "--summary", str(spec))
    assert result.returncode == 0, result.stderr
    assert "mono microphone moving (line, 1.5 m, facing fixed)" in result.stdout
    assert "(estimate; pairs with the microphone)" in result.stdout
    per_source = [int(out.split("about ")[1].split()[0]) for out in (still, result.stdout)]
    assert per_source[1] == per_source[0] + 7


def test_full_plan_of_the_demo(tmp_path: Path) -> None:
    spec = write(tmp_path, "demo.yaml", (ROOT / "specs" / "demo.yaml").read_text())
    result = run_cli("plan", str(spec))
    assert result.returncode == 0, result.stderr
    assert "(no earlier build)" in result.stdout
    assert any(line.split()[:3] == ["rir", "4", "0"] for line in result.stdout.splitlines())
    plan = json.loads(run_cli("plan", "--json", str(spec)).stdout)
    assert plan["steps"]["mesh"] == {"jobs": 3, "in_store": 0, "kept": 0, "added": 3,
                                     "dropped": 0}
    assert plan["store_dir"] == str(tmp_path / "out" / "store")
    # The last build's plan made by another sonicspec version (a stage's version bumped, so
    # one step's keys no longer re-hash) still tells what changed: that step is all new.
    from sonicspec.plan.compile import compile_spec
    from sonicspec.spec import load_spec

    built = compile_spec(load_spec(spec)).to_dict()
    for job in built["jobs"]:
        if job["step"] == "rir":
            job["key"] = "0" * 64
    last = tmp_path / "out" / "store" / "plans" / "last-build-demo.json"
    last.parent.mkdir(parents=True)
    last.write_text(json.dumps(built))
    plan = json.loads(run_cli("plan", "--json", str(spec)).stdout)
    assert plan["steps"]["mesh"]["kept"] == 3 and plan["steps"]["mesh"]["added"] == 0
    assert plan["steps"]["rir"]["added"] == 4 and plan["steps"]["rir"]["dropped"] == 1


def test_plan_on_invalid_spec_exits_2(tmp_path: Path) -> None:
    path = write(tmp_path, "bad.yaml", yaml.safe_dump({"sonicspec": 1}))
    result = run_cli("plan", str(path))
    assert result.returncode == 2 and "required field missing" in result.stderr


def test_bad_arguments_exit_2() -> None:
    assert run_cli("validate").returncode == 2
    assert run_cli("init", "--preset", "nonsense").returncode == 2


def test_plan_summary_needs_no_data_and_says_what_to_get(tmp_path: Path) -> None:
    """Issue 28 item 12: `plan --summary` of the SonicSet preset without its data exited 2
    ("glob 'data/mp3d/*/*.glb' matches no file") though its help says no data is needed."""
    spec = write(tmp_path, "sonicset.yaml", (ROOT / "specs" / "sonicset.yaml").read_text())
    result = run_cli("plan", "--summary", str(spec))
    assert result.returncode == 0, result.stderr
    rows = {line.split()[0]: line.split()[1:] for line in result.stdout.splitlines()
            if line.split() and line.split()[0] in ("train", "val", "test")}
    assert rows["train"][:3] == ["?", "?", "?"] and rows["test"][2] == "247"
    assert "to build it, get:" in result.stdout
    for needed in ("scenes[0] (mp3d): no file matches 'data/mp3d/*/*.glb'",
                   "data/mp3d/<building id>/<building id>.glb",
                   "corpora.speech (librispeech)", "train-clean-360",
                   "<speaker>-<chapter>.trans.txt", "FSD50K.ground_truth/dev.csv",
                   "fma_metadata/tracks.csv"):
        assert needed in result.stdout, needed
    # One fake scan: the plan's error is one clear sentence, then what to get.
    scan = tmp_path / "data" / "mp3d" / "abc" / "abc.glb"
    scan.parent.mkdir(parents=True)
    scan.write_bytes(b"glTF")
    result = run_cli("plan", str(spec))
    assert result.returncode == 2
    assert ("splits.train.scene_count: asks for 62 scenes, but only 1 of the scenes it "
            "matches is not taken by earlier splits (1 matched in all); add scenes or lower "
            "scene_count") in result.stderr, result.stderr
    assert "corpora.speech (librispeech): no folder" in result.stderr


def test_help_says_what_each_command_does_and_hides_the_internal_one() -> None:
    """Issue 28 item 14: `job` (the workflow's) was in the top-level help; `evaluate --task`
    and `export --format` had no help; `init` promised a "commented starting spec" (it writes
    a preset); `validate --check-files` said it checks that meshes exist (it loads them)."""
    top = run_cli("--help").stdout
    assert not re.search(r"^\s+job\b", top, re.M) and "SUPPRESS" not in top
    assert run_cli("job", "--help").returncode == 0  # still there for the workflow
    evaluate = run_cli("evaluate", "--help").stdout
    assert re.search(r"--task \{separation,enhancement\}\s+which mixtures to score", evaluate)
    export = run_cli("export", "--help").stdout
    assert re.search(r"--format \{huggingface,webdataset\}\s+huggingface: Parquet", export)
    assert "'validation'" in export
    assert "write one of the preset specs" in top
    assert "commented starting spec" not in top
    validate = " ".join(run_cli("validate", "--help").stdout.split())
    assert "load every referenced mesh through the build's reader" in validate


def test_pyproject_license_is_an_spdx_expression() -> None:
    """Issue 28 item 14: the TOML-table `project.license` printed setuptools' deprecation
    (builds stop after 2027-02-18); PEP 639's SPDX string needs setuptools >= 77."""
    import tomllib

    project = tomllib.loads((ROOT / "pyproject.toml").read_text())
    assert project["project"]["license"] == "Apache-2.0"
    assert project["build-system"]["requires"] == ["setuptools>=77"]
    assert not any("License ::" in c for c in project["project"].get("classifiers", []))
