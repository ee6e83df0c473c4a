"""MkDocs hooks: the generated parts of the site, made at every build from the code.

* ``<!-- generated: spec -->`` in a page becomes the spec reference
  (:func:`sonicspec.spec.reference.spec_reference`, from the spec models);
* ``<!-- generated: cli -->`` becomes the command-line reference, walked from the argparse
  parser the ``sonicspec`` command itself uses (``sonicspec.cli.build_parser``);
* ``<!-- generated: steps -->`` becomes the table of the pipeline's steps
  (``sonicspec.plan.model.STEPS``);
* the benchmark figures (``bench/figures/*.png``) are served as ``figures/<name>.png``
  without copying them into ``docs/``, so ``bench/RESULTS.md`` (included in the benchmarks
  page) and the science pages show the files the bench scripts write.

Nothing is fetched from the network. The tests (``tests/test_docs.py``) load this file too.
"""

from __future__ import annotations

import argparse
import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
FIGURES = ROOT / "bench" / "figures"
MARKER = re.compile(r"<!-- generated: (\w+) -->")


# ---------------------------------------------------------------- the command-line reference


Command = tuple[str, str, argparse.ArgumentParser]


def _subcommands(parser: argparse.ArgumentParser) -> list[Command]:
    """(name, help, parser) of each subcommand, in the order they were added."""
    out = []
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            helps = {a.dest: a.help or "" for a in action._choices_actions}
            out += [(name, helps.get(name, ""), sub) for name, sub in action.choices.items()]
    return out


def commands(parser: argparse.ArgumentParser, prefix: str = "") -> list[Command]:
    """Every command and subcommand, depth first: (``"scene inspect"``, help, its parser)."""
    out = []
    for name, help_text, sub in _subcommands(parser):
        full = f"{prefix} {name}".strip()
        out.append((full, help_text, sub))
        out += commands(sub, full)
    return out


def _flags(action: argparse.Action) -> str:
    if not action.option_strings:
        return f"`{action.metavar or action.dest}`"
    metavar = action.metavar
    if action.nargs == 0:
        value = ""
    elif isinstance(metavar, tuple):
        value = " " + " ".join(metavar)
    else:
        value = " " + (metavar or action.dest.upper())
        if action.nargs in ("+", "*"):
            value += " ..."
    return ", ".join(f"`{flag}{value}`" for flag in action.option_strings)


def _argument_row(action: argparse.Action) -> str:
    notes = []
    if action.choices is not None and not isinstance(action, argparse._SubParsersAction):
        notes.append("one of " + ", ".join(f"`{c}`" for c in action.choices))
    if action.required and action.option_strings:
        notes.append("required")
    if action.nargs == "+" and not action.option_strings:
        notes.append("one or more")
    if action.nargs == "?" and not action.option_strings:
        notes.append("optional")
    if action.option_strings and action.nargs == argparse.ZERO_OR_MORE:
        notes.append("zero or more")
    if isinstance(action, argparse._AppendAction):
        notes.append("repeatable")
    text = " ".join((action.help or "").split()).replace("|", "\\|").replace("<", "&lt;")
    if notes:
        text = f"{text} ({'; '.join(notes)})" if text else "; ".join(notes)
    return f"| {_flags(action)} | {text} |"


def _arguments(parser: argparse.ArgumentParser) -> list[str]:
    lines = []
    for group in parser._action_groups:
        actions = [a for a in group._group_actions
                   if a.help != argparse.SUPPRESS and not isinstance(a, (
                       argparse._HelpAction, argparse._SubParsersAction))]
        if not actions:
            continue
        title = {"positional arguments": "Arguments", "options": "Options",
                 "optional arguments": "Options"}.get(group.title or "", group.title or "")
        lines += [f"**{title[:1].upper()}{title[1:]}**", ""]
        if group.description:
            lines += [" ".join(group.description.split()), ""]
        lines += ["| argument | meaning |", "| --- | --- |"]
        lines += [_argument_row(a) for a in actions]
        lines.append("")
    return lines


def _usage(parser: argparse.ArgumentParser) -> str:
    # A fixed width, so the page does not depend on the terminal that builds it.
    formatter = argparse.HelpFormatter(parser.prog, width=96)
    formatter.add_usage(parser.usage, parser._actions, parser._mutually_exclusive_groups)
    return formatter.format_help().strip()


def anchor(command: str) -> str:
    """The heading id of a command's section (``scene inspect`` → ``scene-inspect``)."""
    return command.replace(" ", "-")


def cli_reference(parser: argparse.ArgumentParser | None = None) -> str:
    """Markdown for every command of ``parser`` (default: the ``sonicspec`` command's)."""
    if parser is None:
        from sonicspec.cli import build_parser

        parser = build_parser()
    parser.prog = "sonicspec"
    listed = commands(parser)
    lines = ["| command | what it does |", "| --- | --- |"]
    lines += [f"| [`sonicspec {name}`](#{anchor(name)}) | "
              f"{' '.join(help_text.split()).replace('|', chr(92) + '|')} |"
              for name, help_text, _ in listed]
    lines += ["", "```text", _usage(parser), "```", ""]
    lines += _arguments(parser)
    for name, help_text, sub in listed:
        level = "###" if " " in name else "##"
        lines += [f"{level} sonicspec {name} {{#{anchor(name)}}}", ""]
        if help_text:
            lines += [" ".join(help_text.split()).rstrip(".") + ".", ""]
        if sub.description:
            lines += [" ".join(sub.description.split()), ""]
        lines += ["```text", _usage(sub), "```", ""]
        lines += _arguments(sub)
    return "\n".join(lines).rstrip() + "\n"


# ---------------------------------------------------------------- the pipeline's steps


def steps_table() -> str:
    """The pipeline's steps in order, with their output versions and resource requests."""
    from sonicspec.plan.model import STEPS

    lines = ["| step | what a job does | stage version | threads | memory (MB) | runtime (min) |",
             "| --- | --- | --- | --- | --- | --- |"]
    lines += [f"| `{s.name}` | {s.description} | {s.version} | {s.threads} | {s.mem_mb} | "
              f"{s.runtime_min} |" for s in STEPS]
    return "\n".join(lines) + "\n"


# ---------------------------------------------------------------- the hooks


def generated(name: str) -> str:
    """The Markdown a ``<!-- generated: NAME -->`` marker stands for."""
    if name == "spec":
        from sonicspec.spec.reference import spec_reference

        return spec_reference()
    if name == "cli":
        return cli_reference()
    if name == "steps":
        return steps_table()
    raise ValueError(f"docs: unknown generated block {name!r}; expected 'spec', 'cli' or "
                     "'steps'")


def expand(markdown: str) -> str:
    """A page's Markdown with every generated marker replaced by its text."""
    return MARKER.sub(lambda m: generated(m.group(1)), markdown)


def on_page_markdown(markdown: str, page, config, files) -> str:
    return expand(markdown)


def on_files(files, config):
    from mkdocs.structure.files import File

    for png in sorted(FIGURES.glob("*.png")):
        files.append(File.generated(config, f"figures/{png.name}", abs_src_path=str(png)))
    return files
