"""A griffe extension for the API pages: the docstrings' reST roles (:class:`X`) become Markdown code (`X`).

The docstrings are written for ``help()`` in a terminal and use a few Sphinx roles; Markdown has
none, so without this the pages would show ``:class:`` in front of every name.
"""

import re

import griffe

_ROLE = re.compile(r":(?:py:)?(?:class|func|meth|mod|data|attr|exc|obj):`~?([^`]+)`")


class RstRoles(griffe.Extension):
    """Rewrite ``:role:`name``` to ```name``` in every docstring griffe loads."""

    def on_instance(self, *, obj, **kwargs) -> None:
        if obj.docstring is not None:
            obj.docstring.value = _ROLE.sub(r"`\1`", obj.docstring.value)
