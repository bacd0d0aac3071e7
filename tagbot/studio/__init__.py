"""The studio: design tags interactively in the browser (paper §5 and §6.6), and draw them.

``tagbot studio [PLAN|INPUT]`` serves a local page (127.0.0.1 only, a session token in the URL)
over the same library: gestures are fitted with :func:`tagbot.fit`, edits rebuild the
:class:`~tagbot.model.plan.Tag` and resample it, previews come from :mod:`tagbot.render`, and
draws go through :mod:`tagbot.draw`. :mod:`tagbot.studio.design` holds the editable design and
its operations, :mod:`tagbot.studio.server` the web app and its JSON API.
"""

from tagbot._lazy import lazy_exports

__all__ = ["Design", "History", "StudioError", "apply", "empty_design", "view"]

__getattr__, __dir__ = lazy_exports(__name__, dict.fromkeys(__all__, ".design"))
