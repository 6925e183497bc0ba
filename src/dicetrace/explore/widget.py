"""The explorer as a Jupyter widget (anywidget): the page in an IFrame, its picks and views sent back to Python.

>>> ex = Explorer(window="red-sea")                         # doctest: +SKIP
>>> w = ex.widget(on_pick=lambda info: print(info["outcome"]))  # doctest: +SKIP
>>> w                                                        # the cell shows it  # doctest: +SKIP

The page, when it runs inside a frame, posts each change of its picked
throws and of its view to the frame's parent (``window.postMessage``, a
message ``{"source": "dicetrace-explore", "type": "throws" | "view", ...}``).
The widget's front end takes only messages from its own IFrame and sets the
synced traits ``throws`` (the hover info of each picked throw, the newest
last, as ``/api/hover`` returns it) and ``view`` (the view's URL
parameters), so Python can ``observe`` them.
"""

from __future__ import annotations

import anywidget
import traitlets

#: The widget's front end: an IFrame of the explorer, and the page's messages to the synced traits.
ESM = r"""
function render({ model, el }) {
  const frame = document.createElement("iframe");
  frame.src = model.get("url");
  frame.title = "dicetrace explore";
  frame.style.cssText = `width:100%;height:${model.get("height")}px;border:0`;
  el.append(frame);
  const onMessage = (ev) => {
    const m = ev.data;
    if (ev.source !== frame.contentWindow || !m || m.source !== "dicetrace-explore") return;
    if (m.type === "throws") model.set("throws", m.throws);
    else if (m.type === "view") model.set("view", m.view);
    else return;
    model.save_changes();
  };
  window.addEventListener("message", onMessage);
  return () => window.removeEventListener("message", onMessage);
}
export default { render };
"""


class ExplorerWidget(anywidget.AnyWidget):
    """The explorer served at ``url`` in a widget; ``throws`` and ``view`` follow the page (see the module)."""

    _esm = ESM
    url = traitlets.Unicode("").tag(sync=True)
    height = traitlets.Int(900).tag(sync=True)
    throws = traitlets.List([]).tag(sync=True)
    view = traitlets.Dict({}).tag(sync=True)

    def on_pick(self, callback) -> None:
        """Call ``callback(info)`` with the hover info of each throw picked on the page (click or shift-click)."""

        def changed(change) -> None:
            new, old = change["new"], change["old"] or []
            if new and (len(new) > len(old) or new[-1] != old[-1]):
                callback(new[-1])

        self.observe(changed, names="throws")
