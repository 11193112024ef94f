"""Every public function of the core packages (common, lidar, registration, vision) is annotated, so
mypy (run by './run test') checks its callers."""
import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
CORE = ("common", "lidar", "registration", "vision")


def _public_functions(tree):
    """Module-level functions and methods of module-level classes whose names are public."""
    for node in tree.body:
        if isinstance(node, ast.FunctionDef) and not node.name.startswith("_"):
            yield node.name, node
        elif isinstance(node, ast.ClassDef) and not node.name.startswith("_"):
            for item in node.body:
                if isinstance(item, ast.FunctionDef) and not item.name.startswith("_"):
                    yield f"{node.name}.{item.name}", item


def test_public_functions_of_the_core_are_annotated():
    missing = []
    for pkg in CORE:
        for path in sorted((ROOT / pkg).rglob("*.py")):
            for name, fn in _public_functions(ast.parse(path.read_text())):
                a = fn.args
                params = [x for x in a.posonlyargs + a.args + a.kwonlyargs if x.arg not in ("self", "cls")]
                params += [x for x in (a.vararg, a.kwarg) if x is not None]
                bare = [x.arg for x in params if x.annotation is None]
                if bare or fn.returns is None:
                    missing.append(f"{path.relative_to(ROOT)}: {name}" + (f" ({', '.join(bare)})" if bare else "")
                                   + ("" if fn.returns is not None else " (return)"))
    assert not missing, "annotate these public functions:\n" + "\n".join(missing)
