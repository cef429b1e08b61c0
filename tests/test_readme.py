"""The README's library example runs as written."""

import re
from pathlib import Path


def test_readme_python_example_runs(ctx, capsys):
    text = (Path(__file__).parent.parent / "README.md").read_text()
    blocks = re.findall(r"```python\n(.*?)```", text, re.S)
    assert blocks
    exec(compile(blocks[0], "README.md", "exec"), {})
    out = capsys.readouterr().out
    assert "TileKey(level=" in out and "->" in out
