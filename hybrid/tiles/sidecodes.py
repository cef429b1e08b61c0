"""Side-error codes: a node's four stitched-triangle errors (W, E, S, N, metres) packed into one float32 beside its
effective error, relative to its parent's effective error, as the GPU selection and the triangle estimate read them.

In the node arrays' fourth column: 0 beyond the node square, else 1 + sum(code << 6 side). A code is
8 log2(side / the parent's effective error) + 56, rounded up, so a side reads back as the parent's
2^((code - 56) / 8), never below the measured one; 63 stands for any larger ratio (the midpoint stays), 0 for 2^-7
or less. A leaf's parent splits, so only sides below it matter. Exact integers up to 2^24.
"""

from __future__ import annotations

import numpy as np

SIDE_STEPS = 8  # side-error codes an octave of side error / the parent's effective error
SIDE_BITS = 6  # bits a side: codes 0 .. 62 a ratio 2^((code - SIDE_BIAS) / 8), 63 any larger
SIDE_BIAS = 56  # code 0: 2^-7 of the parent's error or less
ALWAYS = (1 << SIDE_BITS) - 1  # the code of a midpoint that always stays
SIDE_FORM = "sides"  # a store's ``nodes`` attribute "form" when its node arrays carry side codes


def holds_side_codes(group) -> bool:
    """Whether a tile store group's node arrays carry side codes (else one error over both fans, no codes)."""
    return dict(group.attrs.get("nodes") or {}).get("form") == SIDE_FORM


def stored_codes(group, levels: int) -> tuple | None:
    """A store group's side-code arrays by global level (``nodes/sides/<g>``), None where it holds none."""
    return tuple(group[f"nodes/sides/{lev}"] for lev in range(levels)) if holds_side_codes(group) else None


def per_child(parent: np.ndarray) -> np.ndarray:
    """(1, 2N, 2N) float64: each of an (N, N) level's node values over its four children, for sides (4, ...)."""
    return np.repeat(np.repeat(np.asarray(parent, np.float64), 2, axis=0), 2, axis=1)[None]


def side_codes(sides: np.ndarray, effective: np.ndarray, parent: np.ndarray | None) -> np.ndarray:
    """Nodes' four side errors (4, N, N) W, E, S, N in metres (read as at least their effective errors (N, N)) as
    the float32 1 + sum(code << 6 side), against their parents' effective errors (N/2, N/2); a node without a
    parent (``parent`` None: the grid's root) gets 63 on every side."""
    return side_codes_each(sides, effective, None if parent is None else per_child(parent)[0])


def side_codes_each(sides: np.ndarray, effective: np.ndarray, parent_each: np.ndarray | None) -> np.ndarray:
    """``side_codes`` with each node's parent's effective error given per node (the nodes' shape)."""
    S = np.maximum(sides, np.asarray(effective).astype(np.float64)[None])
    if parent_each is None:
        code = np.full(S.shape, ALWAYS)
    else:
        P = np.asarray(parent_each, np.float64)[None]
        with np.errstate(divide="ignore", invalid="ignore"):
            ratio = np.where(P > 0, S / np.where(P > 0, P, 1.0), np.where(S > 0, np.inf, 0.0))
            code = np.ceil(SIDE_STEPS * np.log2(ratio) + SIDE_BIAS - 1e-9)
        code = np.where(code > ALWAYS - 1, ALWAYS, np.maximum(code, 0))
    packed = (code.astype(np.int64) << (SIDE_BITS * np.arange(4))[:, None, None]).sum(axis=0) + 1
    return packed.astype(np.float32)


def decoded_sides(w: np.ndarray, parent: np.ndarray | None) -> np.ndarray:
    """(4, ...) side errors (metres) W, E, S, N of nodes from their fourth column (``side_codes``) and their parents'
    effective errors (None: no parent), as the GPU selection reads them (inf: the midpoint always stays)."""
    code = (np.asarray(w).astype(np.int64) - 1)[None] >> (SIDE_BITS * np.arange(4))[:, None, None] & ALWAYS
    if parent is None:
        return np.full(code.shape, np.inf)
    return np.where(code == ALWAYS, np.inf, per_child(parent) * np.exp2((code - SIDE_BIAS) / SIDE_STEPS))
