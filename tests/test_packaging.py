"""Every file the packages load at run time is declared as package data, so an installed copy works."""

import fnmatch
import tomllib
from pathlib import Path

ROOT = Path(__file__).parent.parent


def test_package_data_covers_every_resource():
    cfg = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]
    patterns = cfg["package-data"]
    for pkg in cfg["packages"]:
        for f in (ROOT / pkg).rglob("*"):
            if f.is_dir() or f.suffix in (".py", ".pyc") or "__pycache__" in f.parts:
                continue
            rel = f.relative_to(ROOT / pkg).as_posix()
            assert any(fnmatch.fnmatch(rel, p) for p in patterns.get(pkg, [])), f"{pkg}/{rel} is not package data"
