"""A griffe extension for the docs site: the reStructuredText of our docstrings read as Markdown.

The docstrings are numpydoc, written for ``help()`` and Sphinx-style readers: cross-reference
roles (``:func:`compute_rir```, ``:class:`~sonicspec.geometry.mesh.SceneMesh```) become code
spans naming the object, and a doctest (``>>>`` lines up to the next blank line) becomes a
``pycon`` code block instead of Markdown quotes.
"""

from __future__ import annotations

import re
from typing import Any

import griffe

ROLE = re.compile(r":(?:py:)?(?:meth|func|class|mod|attr|data|exc|obj|const):`~?\.?([^`]+)`")


def _role(match: re.Match[str]) -> str:
    target = match.group(1)
    if match.group(0).split("`", 1)[1].startswith("~"):
        target = target.rsplit(".", 1)[-1]
    return f"`{target}`"


def markdown(text: str) -> str:
    """A docstring's text with roles as code spans and doctests fenced."""
    text = ROLE.sub(_role, text)
    out: list[str] = []
    in_doctest = False
    for line in text.splitlines():
        if not in_doctest and line.lstrip().startswith(">>> "):
            out.append("```pycon")
            in_doctest = True
        elif in_doctest and not line.strip():
            out.append("```")
            in_doctest = False
        out.append(line)
    if in_doctest:
        out.append("```")
    return "\n".join(out)


class RstToMarkdown(griffe.Extension):
    def on_instance(self, *, obj: griffe.Object, **kwargs: Any) -> None:
        if obj.docstring is not None:
            obj.docstring.value = markdown(obj.docstring.value)
