"""Griffe extension for the jaxbelt documentation: units in square brackets stay text.

jaxbelt's docstrings write units in square brackets ("over [t0, t1] [s]"). Markdown reads a
bracket pair followed by another ("[t0, t1] [s]") as a reference link with id "s", and the
strict docs build then fails on an unknown cross-reference. This extension escapes the second
bracket of such pairs (outside code spans and $...$ math) before the docstring is rendered, so
the text reads as written. It changes nothing in the package itself.
"""

from __future__ import annotations

import re

from griffe import Extension

# "]" + at most one blank + "[" : the shape of a Markdown reference link "[text] [id]".
_PAIR = re.compile(r"\](\s?)\[(?=[^\]\n]*\])")
# code spans and math are left alone
_PROTECTED = re.compile(r"(`+)(?:.|\n)*?\1|\$\$(?:.|\n)*?\$\$|\$[^$\n]+\$")


def escape_unit_brackets(text: str) -> str:
    """Escape the second bracket of every "[...] [...]" pair outside code and math."""
    out, pos = [], 0
    for m in _PROTECTED.finditer(text):
        out.append(_PAIR.sub(r"]\1\\[", text[pos:m.start()]))
        out.append(m.group(0))
        pos = m.end()
    out.append(_PAIR.sub(r"]\1\\[", text[pos:]))
    return "".join(out)


class UnitBrackets(Extension):
    """Apply `escape_unit_brackets` to every docstring as it is loaded."""

    def on_instance(self, *, obj, **kwargs) -> None:  # noqa: D102
        if obj.docstring is not None:
            obj.docstring.value = escape_unit_brackets(obj.docstring.value)
