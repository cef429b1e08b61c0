"""The report's reading: sentences generated from a run's frames table, ranking only what noise cannot explain.

Timing statements go through ``experiments.noise``: a difference within the noise of the same run is called
within noise, never ranked. A mixed policy (hybrid, heuristic, oracle) that made the same per-tile choices as a
pure method in every frame is named as such. Accuracy and coverage statements are deterministic (the same frame
renders the same pixels) and use the measures of ``experiments.metrics`` and ``experiments.popping``.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from hybrid.strategies import mixed_policies

from .adapt_charts import adaptation_sentences, gpu_cpu_sentence
from .charts import label_columns
from .noise import compare


def _fmt_list(items: list[str]) -> str:
    return items[0] if len(items) == 1 else ", ".join(items[:-1]) + " and " + items[-1]


def speed_sentence(scene: str, g: pd.DataFrame) -> str:
    """Which methods are fastest in a scene, the ties with the fastest named as ties, and the next one's ratio."""
    ms = g.groupby("method")["wall_ms"].median().sort_values()
    first = ms.index[0]
    if len(ms) == 1:
        return f"**{scene}**: {first} at {ms.iloc[0]:.1f} ms median per frame."
    by = {m: g[g["method"] == m] for m in ms.index}
    cmp = {m: compare(m, by[m], first, by[first]) for m in ms.index[1:]}
    tied = [m for m in ms.index[1:] if cmp[m].tie]
    rest = [m for m in ms.index[1:] if not cmp[m].tie]
    s = f"**{scene}**: the lowest median frame time is {first}'s ({ms[first]:.1f} ms)"
    if tied:
        s += f"; {'within noise of it' if rest else 'every other method within noise of it'}: " + ", ".join(
            f"{m} ({ms[m]:.1f} ms)" for m in tied
        )
    if rest:
        c = cmp[rest[0]]
        s += f"; the next, {rest[0]} ({c.ms_a:.1f} ms), is {c.words()} than {first}"
    return s + "."


def _same_choices(rows: pd.DataFrame) -> str | None:
    """'raster', 'raster_gs' or 'raycast' when a mixed policy's rows chose that strategy for every tile of every
    frame."""
    if "tiles_raster" not in rows or rows["tiles"].sum() == 0:
        return None
    gs = int(rows["tiles_gs"].sum()) if "tiles_gs" in rows else 0
    raster = int(rows["tiles_raster"].sum())
    if rows["tiles_raycast"].sum() == 0:
        return "raster_gs" if gs == raster else "raster" if gs == 0 else None
    if raster == 0:
        return "raycast"
    return None


def mixed_sentences(g: pd.DataFrame) -> list[str]:
    """Per mixed policy and tau: its choices against the pure methods' at the same tau, and its time against
    theirs (and the oracle's), ties called within noise."""
    out = []
    for (tau, rec, fr), sub in g.groupby(["tau", "reconstruction", "full_res"]):
        pure = {p: sub[sub["policy"] == p] for p in ("raster", "raster_gs", "raycast")}
        for p in ("raster", "raster_gs", "raycast"):  # raster runs once, with the first reconstruction; ray
            if pure[p].empty:  # casting once, with the exact full-resolution rule
                same = (g["policy"] == p) & (g["tau"] == tau)
                pure[p] = g[same & (g["full_res"] == fr)] if p != "raycast" else g[same & (g["reconstruction"] == rec)]
        pure = {p: r for p, r in pure.items() if not r.empty}
        if not pure:
            continue
        for pol, name in [
            (p, m) for p in mixed_policies() for m in sorted(sub.loc[sub["policy"] == p, "method"].unique())
        ]:
            rows = sub[sub["method"] == name]
            same = _same_choices(rows)
            if same and same in pure:
                c = compare(name, rows, pure[same]["method"].iloc[0], pure[same])
                s = f"{name}: the same choices as {same} in every frame ({c.ms_a:.1f} vs {c.ms_b:.1f} ms), "
                if c.tie:
                    s += f"difference {c.words()}"
                else:
                    s += f"yet {c.words()}"
                    if "plan_ms" in rows and rows["plan_ms"].notna().any():
                        s += f"; it plans each frame ({rows['plan_ms'].median():.2f} ms median)"
                out.append(s + ".")
                continue
            n = max(rows["tiles"].sum(), 1)
            share = rows["tiles_raster"].sum() / n if "tiles_raster" in rows else np.nan
            gs = rows["tiles_gs"].sum() / n if "tiles_gs" in rows else 0.0
            best = min(pure, key=lambda p: pure[p]["wall_ms"].median())
            c = compare(name, rows, pure[best]["method"].iloc[0], pure[best])
            split = f" ({100 * gs:.0f} % through the geometry shader)" if gs > 0 else ""
            s = (
                f"{name}: rasterizes {100 * share:.0f} % of its tiles{split}; against the best pure method "
                f"({best}, {c.ms_b:.1f} ms) it takes {c.ms_a:.1f} ms, {c.words()}"
            )
            oracle = sub[sub["policy"] == "oracle"]
            if pol != "oracle" and not oracle.empty:
                o = compare(name, rows, oracle["method"].iloc[0], oracle)
                s += f"; against the oracle ({o.ms_b:.1f} ms) {o.words()}"
            out.append(s + ".")
    return out


def _popping_sentence(g: pd.DataFrame) -> str:
    """Pixels each method flags as popping over the flight, beside what it flags with its level of detail held
    (``pop_static_px``, where measured): a method flagging no more than that has no level-of-detail popping."""
    pops = g.groupby("method")["pop_px"].sum()
    static = g.groupby("method")["pop_static_px"].sum(min_count=1) if "pop_static_px" in g else None
    parts = []
    for m, v in pops[pops > 0].sort_values(ascending=False).items():
        st = static.get(m) if static is not None else None
        if st is None or not np.isfinite(st):
            parts.append(f"{m} {int(v)} px")
        else:
            parts.append(
                f"{m} {int(v)} px ({int(st)} with its level of detail held"
                + (": no more than without switching" if v <= st else "")
                + ")"
            )
    return (
        "Popping (pixels whose depth error steps by more than 0.1 % of the distance in one frame, on a camera "
        "slow enough to tell): " + (", ".join(parts) + " over the flight" if parts else "none") + "."
    )


def accuracy_sentences(g: pd.DataFrame) -> list[str]:
    """Most and least accurate methods by mean FLIP over terrain pixels (equal values named together); cracks,
    silhouette differences and popping where any method has them."""
    out = []
    if "flip" in g and g["flip"].notna().any():
        acc = g.groupby("method")["flip"].mean().round(5).sort_values()
        lo = acc[acc == acc.iloc[0]].index.tolist()
        hi = acc[acc == acc.iloc[-1]].index.tolist()
        s = f"Most accurate against the reference (mean FLIP over terrain pixels): {_fmt_list(lo)} ({acc.iloc[0]:.4f})"
        if acc.iloc[-1] > acc.iloc[0]:
            s += f"; least: {_fmt_list(hi)} ({acc.iloc[-1]:.4f})"
        out.append(s + ".")
    if "crack_px" in g:
        cracks = g.groupby("method")["crack_px"].max()
        bad = cracks[cracks > 0]
        out.append(
            "Cracks (sky enclosed by the method's own terrain where the reference has terrain): "
            + (", ".join(f"{m} up to {int(v)} px a frame" for m, v in bad.items()) if len(bad) else "none")
            + "."
        )
    if "terrain_as_sky" in g:
        miss = g.groupby("method")["terrain_as_sky"].max()
        worst = miss.idxmax()
        out.append(
            "Reference terrain drawn as sky (cracks and silhouettes): "
            + (
                f"at most {100 * miss[worst]:.3g} % of its terrain pixels in a frame ({worst})"
                if miss[worst] > 0
                else "none"
            )
            + "."
        )
    if "pop_px" in g and g["pop_px"].notna().any():
        out.append(_popping_sentence(g))
    for col, what in (("capped_rays", "capped rays"), ("nan_px", "NaN pixels")):
        if col in g and g[col].fillna(0).max() > 0:
            s = g.groupby("method")[col].max()
            out.append(f"{what}: " + ", ".join(f"{m} {int(v)}" for m, v in s[s > 0].items()) + ".")
    return out


def reading(frames: pd.DataFrame, errors: list[dict]) -> list[str]:
    """Sentences per scene: speed (ties within noise named as ties), mixed policies' choices and times, accuracy
    and failures, then the hybrids' adaptation and GPU against CPU time; indented lines belong to the scene line
    above them."""
    f = label_columns(frames)
    out = []
    for sc, g in f.groupby("scene"):
        out.append(speed_sentence(sc, g))
        out += ["  " + s for s in mixed_sentences(g) + accuracy_sentences(g)]
    for e in errors:
        out.append(f"Configuration {e.get('config')} failed: {e.get('error')}.")
    return out + adaptation_sentences(f) + [gpu_cpu_sentence(f)]
