"""The architecture's import rules hold (import-linter contracts in pyproject.toml)."""
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_import_contracts_are_kept():
    lint = Path(sys.executable).with_name("lint-imports")
    res = subprocess.run([str(lint), "--no-cache"], cwd=ROOT, capture_output=True, text=True)
    assert res.returncode == 0, res.stdout + res.stderr
    assert "0 broken" in res.stdout


PACKAGES = ("app", "common", "lidar", "registration", "vision", "projects")
#: Import cycles tolerated: none.
KNOWN_CYCLES: list[set[str]] = []


def _cycles() -> list[set[str]]:
    """The groups of modules that import each other (strongly connected components of the import graph)."""
    import grimp

    graph = grimp.build_graph(*PACKAGES, cache_dir=None, exclude_type_checking_imports=True)
    adj = {m: sorted(graph.find_modules_directly_imported_by(m)) for m in sorted(graph.modules)}
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    out: list[set[str]] = []

    def strong(v: str) -> None:  # Tarjan's algorithm
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in adj[v]:
            if w not in index:
                strong(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            group = set()
            while True:
                w = stack.pop()
                on.discard(w)
                group.add(w)
                if w == v:
                    break
            if len(group) > 1:
                out.append(group)

    sys.setrecursionlimit(max(sys.getrecursionlimit(), 10 * len(adj)))
    for m in adj:
        if m not in index:
            strong(m)
    return out


def test_no_import_cycles():
    """No two modules import each other, even through imports inside functions (which hide cycles)."""
    cycles = [sorted(c) for c in _cycles() if c not in KNOWN_CYCLES]
    assert not cycles, f"import cycles: {cycles}"


#: Imports inside functions, at most; each says why it is not at the top of its module (see
#: test_every_function_local_import_gives_its_reason). Lower it as they go.
MAX_FUNCTION_IMPORTS = 48  # stage 1 computes with lidar.pipeline imported at its first use (status: -0.4 s)


def _function_imports() -> list[str]:
    """``path:line`` of every import inside a function of our packages."""
    import ast

    found = []
    for pkg in PACKAGES:
        for path in sorted((ROOT / pkg).rglob("*.py")):
            tree = ast.parse(path.read_text(encoding="utf-8"))
            for func in ast.walk(tree):
                if isinstance(func, (ast.FunctionDef, ast.AsyncFunctionDef)):
                    found += [f"{path.relative_to(ROOT)}:{node.lineno}" for node in ast.walk(func)
                              if isinstance(node, (ast.Import, ast.ImportFrom))]
    return sorted(set(found))


def test_function_local_imports_are_counted():
    found = _function_imports()
    assert len(found) <= MAX_FUNCTION_IMPORTS, f"{len(found)} imports inside functions (at most " \
                                               f"{MAX_FUNCTION_IMPORTS}): move them to the top of their modules"


def _reason(lines: list[str], index: int) -> bool:
    """A ``# local: WHY`` comment on the import's line, or on the line above it or above its block of imports."""
    if "# local:" in lines[index]:
        return True
    k = index - 1
    while k >= 0 and (lines[k].lstrip().startswith(("import ", "from ")) or not lines[k].strip()):
        k -= 1
    return k >= 0 and lines[k].lstrip().startswith("# local:")


def test_every_function_local_import_gives_its_reason():
    """An import stays inside a function only for a reason said beside it (a measured start-up gain of a command
    a user waits on, ...): ``# local: WHY`` on its line or on the line above it (or above its block of imports)."""
    unexplained = []
    for where in _function_imports():
        path, line = where.rsplit(":", 1)
        lines = (ROOT / path).read_text(encoding="utf-8").splitlines()
        if not _reason(lines, int(line) - 1):
            unexplained.append(f"{where}: {lines[int(line) - 1].strip()}")
    assert not unexplained, "imports inside functions without a '# local: WHY' comment:\n" + "\n".join(unexplained)


def _dotted(node) -> str | None:
    """``a.b.c`` of an expression made of names and attributes, else None."""
    import ast

    parts = []
    while isinstance(node, ast.Attribute):
        parts.append(node.attr)
        node = node.value
    return ".".join([node.id, *reversed(parts)]) if isinstance(node, ast.Name) else None


def _private_uses(path: Path, source: str) -> list[str]:
    """``from x import _y`` of another module of ours, and ``x._y`` through a module of ours imported as x."""
    import ast

    def private(name: str) -> bool:
        return name.startswith("_") and not name.startswith("__")

    def is_module(dotted: str) -> bool:
        p = ROOT.joinpath(*dotted.split("."))
        return p.with_suffix(".py").exists() or (p / "__init__.py").exists()

    tree = ast.parse(source)
    modules: dict[str, str] = {}  # the names bound to our modules
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and not node.level and node.module.split(".")[0] in PACKAGES:
            for a in node.names:
                if is_module(f"{node.module}.{a.name}"):
                    modules[a.asname or a.name] = f"{node.module}.{a.name}"
                elif private(a.name):
                    found.append(f"{path}:{node.lineno}: from {node.module} import {a.name}")
        elif isinstance(node, ast.Import):
            for a in node.names:
                if a.name.split(".")[0] in PACKAGES:
                    modules[a.asname or a.name] = a.name
    for node in ast.walk(tree):
        if isinstance(node, ast.Attribute) and private(node.attr) and _dotted(node.value) in modules:
            found.append(f"{path}:{node.lineno}: {_dotted(node.value)}.{node.attr}")
    return found


def test_no_module_uses_a_private_name_of_another():
    """What a module keeps to itself (``_name``) is not imported or reached into by another of ours; a private
    module (``_common``) is imported only inside its package (import-linter's private_modules contract)."""
    found = []
    for pkg in PACKAGES:
        for path in sorted((ROOT / pkg).rglob("*.py")):
            found += _private_uses(path.relative_to(ROOT), path.read_text(encoding="utf-8"))
    assert not found, "private names used across modules:\n" + "\n".join(found)


def test_the_private_name_check_finds_both_forms():
    """The check above can fail: both forms it looks for are found in a made-up module."""
    source = "from lidar.systematic.adjustment import _helper\nimport lidar.io.las as las\nx = las._header\n"
    found = _private_uses(Path("made_up.py"), source)
    assert [f.split(": ", 1)[1] for f in found] == ["from lidar.systematic.adjustment import _helper",
                                                    "las._header"]
