"""One way through the code: every import goes down the layers, no import cycle, every module imports alone.

Layers, lowest first: errors -> terrain -> camera -> tiles -> gl -> contract -> the strategies (raster,
raycast; never each other) -> strategies registry -> cost -> reference, residency, renderer -> calibrate ->
experiments. The ``hybrid`` package root imports only the lower layers eagerly (the rest on first use).
"""

import ast
import itertools
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
PACKAGES = ("hybrid", "raster", "raycast", "experiments")
LAYERS = [
    ("hybrid.errors", "hybrid.atomic"),
    ("hybrid.terrain",),
    ("hybrid.camera",),
    ("hybrid.tiles", "hybrid"),  # the package root: eager names of the layers up to here
    ("hybrid.gl",),
    ("hybrid.contract",),
    ("raster", "raycast"),
    ("hybrid.strategies", "hybrid.draw_options"),
    ("hybrid.cost",),
    ("hybrid.oracle", "hybrid.adaptive"),  # the renderer's in-frame timing and online adaptation
    (
        "hybrid.reference_blocks",
        "hybrid.reference",
        "hybrid.residency",
        "hybrid.uploads",
        "hybrid.streaming",
        "hybrid.frame_draw",
        "hybrid.frame_stats",
        "hybrid.frame_readback",
        "hybrid.renderer",
        "hybrid.store_editing",
        "hybrid.editing",
    ),
    ("hybrid.calibrate",),
    ("experiments",),
]
PEERS_APART = {("raster", "raycast"), ("raycast", "raster")}


def modules() -> dict[str, Path]:
    """Every module of the four packages: dotted name -> file."""
    out = {}
    for pkg in PACKAGES:
        for f in (ROOT / pkg).rglob("*.py"):
            parts = list(f.relative_to(ROOT).with_suffix("").parts)
            if parts[-1] == "__init__":
                parts = parts[:-1]
            out[".".join(parts)] = f
    return out


def layer_of(name: str) -> tuple[int, str]:
    """(layer index, layer prefix) of a module: the longest prefix named in LAYERS."""
    best = None
    for i, group in enumerate(LAYERS):
        for prefix in group:
            if name == prefix or name.startswith(prefix + "."):
                if prefix == "hybrid" and name != "hybrid":
                    continue  # only the root itself sits with the tiles layer
                if best is None or len(prefix) > len(best[1]):
                    best = (i, prefix)
    assert best is not None, f"{name} is in no layer"
    return best


def imports(name: str, path: Path, known: set[str]) -> set[str]:
    """Project modules a module imports anywhere in its body (function-level imports too), with the packages
    whose ``__init__`` those imports run: every package above an imported module that is not above ``name``
    (those have run before ``name`` does)."""
    tree = ast.parse(path.read_text())
    is_pkg = path.name == "__init__.py"
    base = name.split(".") if is_pkg else name.split(".")[:-1]
    found = set()
    for node in ast.walk(tree):
        targets = []
        if isinstance(node, ast.Import):
            targets = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            mod = node.module or ""
            if node.level:
                mod = ".".join(base[: len(base) - node.level + 1] + ([mod] if mod else []))
            # "from pkg import mod" imports the module pkg.mod; "from mod import name" imports mod
            targets = [f"{mod}.{a.name}" if f"{mod}.{a.name}" in known else mod for a in node.names]
        for t in targets:
            while t and t not in known:
                t = t.rpartition(".")[0]
            if t and t != name:
                found.add(t)
    return found | {p for t in found for p in packages_above(t) if p in known and p not in packages_above(name)}


def packages_above(name: str) -> set[str]:
    """The dotted names of the packages that hold a module: "a.b.c" -> {"a", "a.b"}."""
    parts = name.split(".")
    return {".".join(parts[:i]) for i in range(1, len(parts))}


def graph() -> dict[str, set[str]]:
    mods = modules()
    known = set(mods)
    return {m: imports(m, p, known) for m, p in mods.items()}


def test_every_import_goes_down_the_layers():
    bad = []
    for m, deps in graph().items():
        lm, pm = layer_of(m)
        for d in deps:
            ld, pd = layer_of(d)
            top = (pm.split(".")[0], pd.split(".")[0])
            if ld > lm or (top in PEERS_APART):
                bad.append(f"{m} (layer {pm}) imports {d} (layer {pd})")
    assert not bad, "imports against the layering:\n" + "\n".join(sorted(bad))


def test_no_import_cycle():
    g = graph()
    index, low, stack, on, cycles = {}, {}, [], set(), []

    def visit(v):  # Tarjan's strongly connected components
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in g[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                cycles.append(sorted(comp))

    for v in g:
        if v not in index:
            visit(v)
    assert not cycles, f"import cycles: {cycles}"


def test_package_inits_and_function_imports_count(tmp_path):
    """Importing a package's module runs the package's ``__init__``, as does an import inside a function."""
    known = set(modules())
    f = tmp_path / "toy.py"
    f.write_text("def later():\n    from experiments.cli.options import from_args\n")
    assert {"experiments.cli.options", "experiments.cli"} <= imports("experiments.toy", f, known)
    assert "experiments.cli" not in imports("experiments.cli.toy", f, known)  # its own package ran already
    assert "hybrid" in graph()["raster.tilelets"]


def test_layers_name_every_subpackage():
    for m in modules():
        layer_of(m)


def third_party() -> set[str]:
    """Every module outside the four packages that one of their files imports (at the top or in a function)."""
    out = set()
    for f in modules().values():
        for node in ast.walk(ast.parse(f.read_text())):
            if isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:  # a name may be a module
                names = [node.module] + [f"{node.module}.{a.name}" for a in node.names]
            else:
                names = []
            out.update(n for n in names if n.split(".")[0] not in PACKAGES)
    return out


def _import_each(names: list[list[str]]) -> list[str]:
    """Import each list of modules in a fresh child of a clean interpreter; the failures' tracebacks."""
    script = (
        "import importlib, os, sys, traceback\n"
        f"sys.path.insert(0, {str(ROOT)!r})\n"
        # third-party libraries load once in the parent: the children test the project's own import order
        f"for lib in {sorted(third_party())!r}:\n"
        "    try:\n"
        "        importlib.import_module(lib)\n"
        "    except Exception:\n"  # not a module, or not installed: the children say so
        "        pass\n"
        "bad = []\n"
        f"for group in {names!r}:\n"
        "    r, w = os.pipe()\n"
        "    pid = os.fork()\n"
        "    if pid == 0:\n"
        "        os.close(r)\n"
        "        try:\n"
        "            for n in group:\n"
        "                importlib.import_module(n)\n"
        "            os._exit(0)\n"
        "        except BaseException:\n"
        "            os.write(w, (repr(group) + '\\n' + traceback.format_exc()).encode())\n"
        "            os._exit(1)\n"
        "    os.close(w)\n"
        "    msg = os.read(r, 1 << 16).decode()\n"
        "    os.close(r)\n"
        "    os.waitpid(pid, 0)\n"
        "    if msg:\n"
        "        bad.append(msg)\n"
        "print('\\n====\\n'.join(bad))\n"
    )
    out = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, cwd=ROOT, timeout=600)
    assert out.returncode == 0, out.stderr
    return [b for b in out.stdout.split("\n====\n") if b.strip()]


@pytest.mark.slow
def test_every_module_imports_alone_and_packages_in_any_order():
    groups = [[m] for m in sorted(modules()) if not m.endswith("__main__")]
    groups += [list(p) for p in itertools.permutations(PACKAGES)]
    failures = _import_each(groups)
    assert not failures, "\n\n".join(failures)
