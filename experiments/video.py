"""The flight as an animation: the reference and every method side by side, frame by frame (imageio GIF)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import numpy.typing as npt
import pandas as pd

from hybrid.atomic import atomic_path
from hybrid.errors import TerrabenchError

from .charts import label_columns


def write_videos(run: Path, frames: pd.DataFrame, out: Path, fps: int = 6) -> list[Path]:
    """One GIF per scene, columns = reference + methods, from the run's saved frame images."""
    try:
        import imageio.v2 as imageio
    except ImportError:
        raise TerrabenchError("--video needs the imageio package (pip install imageio)") from None
    from PIL import Image, ImageDraw

    f = label_columns(frames)
    img = run / "images"
    written = []
    for scene, sf in f.groupby("scene"):
        r0 = sf.iloc[0]
        gid = f"{Path(str(r0['dataset'])).stem}-s{r0['seed']}-{Path(str(r0['flight'])).stem}-{r0['size']}"
        configs = sf.drop_duplicates("config")[["config", "method"]].values.tolist()
        seq: list[npt.ArrayLike] = []  # the frames, as imageio.mimsave takes them
        for k in sorted(sf["frame"].unique()):
            paths = [("reference", img / f"ref-{gid}-f{k}.png")] + [(m, img / f"{c}-f{k}.png") for c, m in configs]
            if not all(p.exists() for _, p in paths):
                continue
            tiles = []
            for name, p in paths:
                im = Image.open(p).convert("RGB")
                ImageDraw.Draw(im).text((4, 4), f"{name}  #{k}", fill=(255, 255, 255))
                tiles.append(np.asarray(im))
            seq.append(np.concatenate(tiles, axis=1))
        if not seq:
            raise TerrabenchError(f"{run}: no per-frame images for {scene}; run the spec with video = true")
        p = out / f"flight_{scene.replace(' / ', '_').replace(' ', '')}.gif"
        with atomic_path(p) as tmp:
            imageio.mimsave(tmp, seq, duration=1.0 / fps, loop=0)
        written.append(p)
    return written
