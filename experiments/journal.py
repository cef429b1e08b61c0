"""A run folder's journal: append-only JSON lines of finished frames (with their tile rows) and of failed
configurations, the tables rewritten from it, and what is still to do.

One finished frame is one line, written in one write and flushed: a kill or a full disk tears at most the last
line, which reading skips. A configuration's result (``experiments.config_task.ConfigResult``) is recorded
here whoever ran it, this process or a cluster worker, so resuming never repeats or loses a frame.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from pathlib import Path
from typing import Protocol, TypeVar

import numpy as np
import pandas as pd

from hybrid.atomic import disk_full, save_npy, save_png, write_parquet
from hybrid.errors import TerrabenchError

from .run_config import RunConfig

C = TypeVar("C", bound=RunConfig)
C_co = TypeVar("C_co", bound=RunConfig, covariant=True)


class RunSpec(Protocol[C_co]):
    """What the journal needs of a spec (a flights or an edit spec): its frame count and its configurations."""

    @property
    def frames(self) -> int:
        """Frames a configuration draws."""
        ...

    def configs(self) -> Sequence[C_co]:
        """Every configuration of the spec."""
        ...


def _jsonable(v):
    if isinstance(v, (np.floating, float)):
        return float(v)
    if isinstance(v, (np.integer,)):
        return int(v)
    return v


class JournalError(TerrabenchError):
    """The run journal cannot be written (disk full, folder gone): the run stops, what was written stays."""


class Journal:
    """Append-only JSON-lines files of a run folder."""

    def __init__(self, folder: Path):
        self.folder = folder

    def rows(self, name: str) -> list[dict]:
        """All rows of a journal file (a torn last line from an interruption is ignored)."""
        p = self.folder / f"{name}.jsonl"
        out = []
        if p.exists():
            for line in p.read_text().splitlines():
                try:
                    out.append(json.loads(line))
                except json.JSONDecodeError:
                    continue
        return out

    def append(self, name: str, rows: list[dict]) -> None:
        """Append rows and flush them to disk."""
        if not rows:
            return
        path = self.folder / f"{name}.jsonl"
        if path.exists() and path.stat().st_size:
            with path.open("rb") as f:  # an interruption may have left a torn last line
                f.seek(-1, 2)
                torn = f.read(1) != b"\n"
            if torn:
                with path.open("a") as f:
                    f.write("\n")
        text = "".join(json.dumps({k: _jsonable(v) for k, v in r.items()}) + "\n" for r in rows)
        try:
            with path.open("a") as f:  # one write: a kill or a full disk tears at most the last line
                f.write(text)
                f.flush()
        except OSError as exc:
            what = "disk full" if disk_full(exc) else (exc.strerror or str(exc))
            raise JournalError(
                f"cannot append to the run journal {path} ({what}); the rows written so far "
                "are kept and the run resumes from them"
            ) from None

    def append_frame(self, row: dict, tiles: list[dict]) -> None:
        """Append one frame's row together with its tile rows as one journal line."""
        self.append("frames", [{**row, "tiles_rows": [{k: _jsonable(v) for k, v in t.items()} for t in tiles]}])

    def write_tables(self) -> None:
        """Rewrite frames.parquet and tiles.parquet from the journal."""
        frames, tiles = [], []
        for r in self.rows("frames"):
            tiles += r.pop("tiles_rows", [])
            frames.append(r)
        for name, rows in (("frames", frames), ("tiles", tiles)):
            if rows:
                write_parquet(self.folder / f"{name}.parquet", pd.DataFrame(rows))


def failed_configs(folder) -> dict[str, str]:
    """Configurations of a run folder that failed and have not finished since: name -> last error."""
    journal = Journal(Path(folder))
    finished = {r["config"] for r in journal.rows("frames")}
    return {e["config"]: e["error"] for e in journal.rows("errors") if e["config"] not in finished}


def pending(spec: RunSpec[C], journal: Journal) -> list[tuple[C, list[int]]]:
    """Every configuration with frames not yet in the journal, and those frames."""
    done = {(r["config"], r["frame"]) for r in journal.rows("frames")}
    out = []
    for c in spec.configs():
        todo = [k for k in range(spec.frames) if (c.config, k) not in done]
        if todo:
            out.append((c, todo))
    return out


def record(folder: Path, journal: Journal, result) -> None:
    """Journal a configuration's result (its frames, or its error) and save its images (a reference image once;
    a failed configuration's references too: they are its group's, rendered once for all its configurations)."""
    if result.error is not None:
        journal.append("errors", [result.error])
    for img in result.images:
        if result.error is not None and not img.stem.startswith("ref-"):
            continue
        path = folder / "images" / f"{img.stem}.png"
        if img.stem.startswith("ref-") and path.exists():
            continue
        save_png(path, img.colour)
        if img.distance is not None:
            save_npy(folder / "images" / f"{img.stem}.depth.npy", img.distance)
            for name, arr in img.maps.items():
                save_npy(folder / "images" / f"{img.stem}.{name}.npy", arr)
    for row, tiles in result.frames:
        journal.append_frame(row, tiles)
