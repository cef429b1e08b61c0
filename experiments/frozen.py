"""Keeping the garbage collector's full passes out of timed frames.

A full (generation 2) pass walks every tracked object; after a renderer's setup those are hundreds of thousands,
so a pass falling inside a streaming frame stalls it by tens of ms. ``frozen_heap`` collects once before the timed
frames and freezes what is left (``gc.freeze``: later passes skip it), then unfreezes and collects after them.
"""

from __future__ import annotations

import contextlib
import gc


@contextlib.contextmanager
def frozen_heap():
    """Collect and freeze the heap for the block (timed frames), then unfreeze and collect it."""
    gc.collect()
    gc.freeze()
    try:
        yield
    finally:
        gc.unfreeze()
        gc.collect()
