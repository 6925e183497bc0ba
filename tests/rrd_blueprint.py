"""The blueprint store of a ``.rrd`` as a tree that two encodings of one blueprint share (ids replaced by positions)."""

from __future__ import annotations

import re
import uuid
from pathlib import Path

import pyarrow as pa
from rerun.chunk import RrdReader

#: Columns that differ between two encodings of the same blueprint.
VOLATILE_COLUMNS = {"rerun.controls.RowId", "RecordingInfo:start_time", "log_time"}
_UUID = re.compile(r"[0-9a-f]{8}-[0-9a-f]{4}-[0-9a-f]{4}-[0-9a-f]{4}-[0-9a-f]{12}")


def blueprint_tree(path: Path) -> dict[str, dict]:
    """The blueprint store as {entity: {component: value}}, ids replaced by tree positions.

    The viewport's root container is ``root``; the i-th entry of container
    ``c`` is ``c.i`` (so ``/view/root.1.0`` is the first view in the second
    entry of the root).  Any id not reached from the root stays ``unreached-N``.
    """
    reader = RrdReader(str(path))
    (store,) = reader.blueprints()
    rows: dict[str, dict] = {}
    for ch in reader.stream(store=store):
        for row in pa.Table.from_batches([ch.to_record_batch()]).to_pylist():
            comp = {k: v for k, v in row.items() if k not in VOLATILE_COLUMNS}
            rows.setdefault(f"{'static' if ch.is_static else 'temporal'} {ch.entity_path}", {}).update(comp)
    names: dict[str, str] = {}
    (viewport,) = [v for k, v in rows.items() if k.endswith(" /viewport")]
    todo = [(str(uuid.UUID(bytes=bytes(viewport["ViewportBlueprint:root_container"][0]))), "root")]
    while todo:
        uid, name = todo.pop()
        names[uid] = name
        for k, v in rows.items():
            if k.endswith(f"/container/{uid}"):
                for i, child in enumerate(v.get("ContainerBlueprint:contents") or []):
                    todo.append((child.split("/", 1)[1], f"{name}.{i}"))

    def canon(obj):
        if isinstance(obj, str):
            return _UUID.sub(lambda m: names.setdefault(m.group(0), f"unreached-{len(names)}"), obj)
        if isinstance(obj, list):
            return [canon(x) for x in obj]
        if isinstance(obj, dict):
            return {canon(k): canon(v) for k, v in obj.items()}
        return obj

    tree = {canon(k): canon(v) for k, v in rows.items()}
    tree["temporal /viewport"]["ViewportBlueprint:root_container"] = "root"
    return tree
