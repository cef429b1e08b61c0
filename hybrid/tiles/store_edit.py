"""An edit written through to a tile store: the chunks it touched, staged and committed at once.

``StoreWrite`` gathers the new contents of whole chunks of a store's arrays: each chunk is read from the store
(checked against the manifest) where the edit does not know it whole, set to what the edit changed, encoded by
Zarr into memory, and staged in a ``hybrid.terrain.store_journal.Transaction``. ``commit`` then stages the manifest (the old one with the new files'
sizes and CRC-32) and the header (updated attributes, the manifest's own size and CRC-32) and commits: a crash at
any point leaves the store wholly before or wholly after the edit. The open store's checked reads learn the new
files. What is written is the touched chunks only: its cost follows the edit, not the store.

``level_chunks`` gives the pyramid levels' chunks over a window of level-0 samples (every level keeps every
2^l-th sample, the last row and column kept: ``store_prepare``).
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from hybrid.errors import TerrabenchError
from hybrid.terrain.edits import Window
from hybrid.terrain.store_journal import Transaction
from hybrid.terrain.store_manifest import HEADER, MANIFEST, crc32, manifest_attribute, manifest_bytes
from hybrid.terrain.stored import StoredTerrain, _zarr


@dataclass
class WriteReport:
    """What a write-through wrote: files (chunks, the manifest and the header) and their bytes."""

    files: int = 0
    bytes: int = 0
    keys: tuple = ()


def level_rows(win_lo: int, win_hi: int, samples: int, level: int) -> np.ndarray:
    """Rows (or columns) of pyramid level ``level`` whose level-0 sample lies in [win_lo, win_hi) of a grid of
    ``samples`` level-0 rows (level row r is level-0 row min(r 2^l, samples - 1))."""
    k = 1 << level
    last = -(-(samples - 1) // k)  # the level's last row: level-0 row samples - 1
    rows = np.arange(-(-win_lo // k), min(-(-win_hi // k), last))
    return np.append(rows, last) if win_lo <= samples - 1 < win_hi else rows


class StoreWrite:
    """The new chunks of one edit of a stored terrain, staged, then committed with the manifest and header."""

    def __init__(self, hf: StoredTerrain):
        if hf.store.attrs.get("periodic"):
            raise TerrabenchError(f"{hf.path}: a periodic extension is served from its source store; edit the source")
        from zarr.storage import MemoryStore

        self.hf, self.root, self.zarr = hf, Path(hf.path), _zarr()
        self.encoded: dict = {}  # key -> Zarr buffer: what the staged arrays wrote
        self.memory = MemoryStore(self.encoded)
        self.staged: dict = {}  # array name -> its staged Zarr array
        self.tx = Transaction(self.root)

    def _stage_array(self, name: str):
        """The array ``name`` over the memory store (its metadata copied there), for encoding whole chunks."""
        if name not in self.staged:
            from zarr.core.buffer import cpu

            self.encoded[f"{name}/{HEADER}"] = cpu.Buffer.from_bytes((self.root / name / HEADER).read_bytes())
            self.staged[name] = self.zarr.open_array(
                store=self.memory, path=name, mode="r+", config={"write_empty_chunks": True}
            )
        return self.staged[name]

    def chunks(self, name: str, chunk_ids, fill, read=True) -> None:
        """Stage chunks ``chunk_ids`` (index tuples) of array ``name``, clipped to the array, a run of neighbours
        along the last chunk axis at a time (one Zarr call): its data read from the store where ``read(starts)`` (or
        ``read`` itself) says so, then ``fill(data, starts)`` sets the new values in place (starts: the run's first
        index per axis; unread data must be filled whole)."""
        src = self.hf.store[name]
        out = self._stage_array(name)
        for first, last in _runs(chunk_ids):
            sel = tuple(
                slice(i * c, min((j + 1) * c, s)) for i, j, c, s in zip(first, last, src.chunks, src.shape, strict=True)
            )
            starts = tuple(x.start for x in sel)
            if read(starts) if callable(read) else read:
                data = np.array(src[sel])
            else:
                data = np.empty(tuple(x.stop - x.start for x in sel), src.dtype)
            fill(data, starts)
            out[sel] = data

    def commit(self, attrs: dict) -> WriteReport:
        """Stage the encoded chunks, the manifest and the header (its attributes updated with ``attrs``), and commit
        them; the open store's checked reads follow. Returns what was written."""
        files = self.hf.store.store.files
        new = dict(files)
        written = sorted(k for k in self.encoded if not k.endswith(HEADER))
        for key in written:
            data = self.encoded[key].to_bytes()
            new[key] = [len(data), crc32(data)]
            self.tx.add(key, data)
        text = manifest_bytes(new)
        header = json.loads((self.root / HEADER).read_bytes())
        header["attributes"] = {**header["attributes"], **attrs, "manifest": manifest_attribute(text, new)}
        head = json.dumps(header, indent=2).encode()
        self.tx.add(MANIFEST, text)
        self.tx.add(HEADER, head)
        self.tx.commit()
        files.clear()
        files.update(new)
        total = sum(new[k][0] for k in written) + len(text) + len(head)
        return WriteReport(len(written) + 2, total, tuple(written))

    def abort(self) -> None:
        """Drop what was staged (nothing reached the store), unless it was committed."""
        self.tx.abort()


def _runs(chunk_ids) -> list[tuple[tuple, tuple]]:
    """(first, last) chunk indices of the runs of consecutive chunks along the last axis among chunk_ids."""
    out: list[tuple[tuple, tuple]] = []
    for idx in sorted(set(map(tuple, chunk_ids))):
        if out and out[-1][1][:-1] == idx[:-1] and out[-1][1][-1] + 1 == idx[-1]:
            out[-1] = (out[-1][0], idx)
        else:
            out.append((idx, idx))
    return out


def level_chunks(levels: int, n: int, win: Window, rows: int, cols: int) -> dict:
    """Per pyramid level, the chunk indices (cy, cx) of ``levels/<l>`` (chunks of n x n samples) holding samples
    that a window of level-0 samples changed."""
    out = {}
    for level in range(levels):
        r, c = level_rows(win.i0, win.i1, rows, level), level_rows(win.j0, win.j1, cols, level)
        if r.size and c.size:
            out[level] = [(int(a), int(b)) for a in np.unique(r // n) for b in np.unique(c // n)]
    return out


def level_fill(heights: np.ndarray, level: int):
    """``StoreWrite.chunks``' fill of a level's chunk from the level-0 heights (float32, metres) in memory."""
    rows, cols = heights.shape
    k = 1 << level

    def fill(data: np.ndarray, starts: tuple) -> None:
        r = np.minimum((starts[0] + np.arange(data.shape[0])) * k, rows - 1)
        c = np.minimum((starts[1] + np.arange(data.shape[1])) * k, cols - 1)
        data[...] = heights[np.ix_(r, c)]

    return fill
