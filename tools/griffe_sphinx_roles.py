"""A griffe extension for the documentation site (mkdocs.yml): Sphinx cross-reference roles become code spans.

dmtrack's docstrings name other objects as Sphinx does (:func:`track`, :class:`~dmtrack.odometry.config.VOConfig`),
which Markdown would show literally. This rewrites each role to a code span of the name it shows
(``~a.b.C`` shows ``C``), before mkdocstrings parses the docstring; the source docstrings stay as they are.
"""

from __future__ import annotations

import re
from typing import Any

import griffe

_ROLE = re.compile(r":(?:py:)?(?:func|class|meth|mod|attr|data|exc|obj|const|term):`(~?)([^`<]+?)`")


def _plain(match: re.Match[str]) -> str:
    name = match.group(2).strip()
    if match.group(1):
        name = name.rsplit(".", 1)[-1]
    return f"`{name}`"


class SphinxRoles(griffe.Extension):
    """Rewrites the Sphinx roles of every docstring griffe loads."""

    def on_instance(self, *, obj: griffe.Object, **kwargs: Any) -> None:
        if obj.docstring is not None:
            obj.docstring.value = _ROLE.sub(_plain, obj.docstring.value)
