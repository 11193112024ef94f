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
#: Import cycles left to the stage-2 move (lidar.systematic is being reshaped): empty this when it is gone.
KNOWN_CYCLES = [{"lidar.systematic.adjustment", "lidar.systematic.walk_screen"}]


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
MAX_FUNCTION_IMPORTS = 38


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
