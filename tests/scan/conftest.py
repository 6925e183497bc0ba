"""Scan-folder fixtures: a folder turned back into the layout of an older dicetrace."""

from __future__ import annotations

import json

import pytest

from dicetrace.scan.folder import LEGACY_CHUNK_LOG, LEGACY_MANIFEST, MANIFEST, ROLLS_DIR, read_chunk_log, read_manifest


def _to_legacy_layout(folder, *, parts_beside: bool = False, chunk_log: bool = True) -> None:
    """Rewrite a scan folder as dicetrace left it before the Parquet manifest: the JSON manifest ``_scan.json``,
    the chunk log ``_scan.chunks.jsonl`` (unless ``chunk_log`` is False: older still) and, with ``parts_beside``,
    the parts beside the manifest instead of in ``rolls/``."""
    manifest, log = read_manifest(folder), read_chunk_log(folder)
    if parts_beside:
        for p in sorted((folder / ROLLS_DIR).iterdir()):
            p.rename(folder / p.name)
        (folder / ROLLS_DIR).rmdir()
    (folder / LEGACY_MANIFEST).write_text(json.dumps({**manifest, "chunk_log": LEGACY_CHUNK_LOG}, indent=1))
    if chunk_log:
        with open(folder / LEGACY_CHUNK_LOG, "w") as f:
            for c in sorted(log):
                e = dict(log[c])
                if parts_beside:
                    e["file"] = e["file"].removeprefix(f"{ROLLS_DIR}/")
                f.write(json.dumps(e, sort_keys=True) + "\n")
    (folder / MANIFEST).unlink()


@pytest.fixture
def to_legacy_layout():
    """A function turning a scan folder into an older dicetrace's layout (see :func:`_to_legacy_layout`)."""
    return _to_legacy_layout
