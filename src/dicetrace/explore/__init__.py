"""``dicetrace explore``: a live, zoomable outcome map served to the browser, with each throw in Rerun's viewer.

>>> from dicetrace.explore import Explorer
>>> Explorer(window="red-sea")          # in Jupyter: the explorer in an IFrame  # doctest: +SKIP
>>> Explorer(window="red-sea").widget(on_pick=print)   # a widget: picks come back  # doctest: +SKIP

:class:`View` (what a map shows, from URL parameters), :func:`compute_map`
(its outcomes through the batch kernel), :func:`create_app` (the ASGI app)
and :class:`Explorer` (served from a background thread).
"""

from dicetrace.explore.compute import Worker, throw_info, throw_rrd
from dicetrace.explore.outcome_map import Cancelled, OutcomeMap, compute_map
from dicetrace.explore.server import Explorer, make_view
from dicetrace.explore.view import MAX_RES, MIN_RES, View, ViewError, view_from_query

__all__ = [
    "MAX_RES",
    "MIN_RES",
    "Cancelled",
    "Explorer",
    "ExplorerWidget",
    "OutcomeMap",
    "View",
    "ViewError",
    "Worker",
    "compute_map",
    "create_app",
    "make_view",
    "throw_info",
    "throw_rrd",
    "view_from_query",
]


def __getattr__(name):  # the server stack (starlette, uvicorn) is imported only when asked for
    if name == "create_app":
        from dicetrace.explore.app import create_app  # starlette, and numba through dicetrace.scan

        return create_app
    if name == "ExplorerWidget":  # anywidget and ipywidgets too
        from dicetrace.explore.widget import ExplorerWidget

        return ExplorerWidget
    raise AttributeError(f"module 'dicetrace.explore' has no attribute {name!r}")
