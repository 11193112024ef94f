"""Code-health figures for issue notes: how often store rows and plan JSON are picked apart outside the
store, and how much of the code is annotated.

Run from the repository root (``python tools/code_metrics.py [ROOT]``); ROOT defaults to ``.`` so an
older checkout can be measured the same way (``git worktree add /tmp/old REV``).

Figures printed:

``row key lookups``
    subscripts with a string literal naming a column of a campaign table (``row["label"]``,
    ``r["displacement_m"]`` ...) in ``app/`` and ``projects/`` outside ``projects/store/campaign.py``;
``plan JSON decodes``
    ``json.loads`` calls on stored rows (any ``json.loads`` in those folders outside the store and
    the file readers that parse user files);
``files running SQL``, ``row accessors``, ``plan decodes``
    what leaks out of the store: modules that execute SQL themselves, calls of accessors that return
    database rows, ``json.loads(row["json"])`` of stored plans;
``annotated parameters``
    the share of function parameters (not ``self``/``cls``) that carry an annotation, per package;
``annotated public functions``
    the share of public functions (no leading underscore) whose parameters and return are all annotated.
"""
from __future__ import annotations

import ast
import re
import sys
from pathlib import Path

PACKAGES = ("common", "lidar", "registration", "vision", "projects", "app")
STORE_COLUMNS = {
    "label", "datetime", "notes", "created", "epoch", "reflector", "grp", "diameter_m", "installed", "retired",
    "replaces", "note", "role", "stored_path", "original_path", "size", "imported", "sha256", "stage",
    "inputs_hash", "processed", "json", "displacement_m", "sigma_m", "flags", "epoch_flags", "baseline",
    "normal_mode", "reference_ids", "details", "median_change_m", "max_change_m", "moved", "missing", "suspect",
    "vertical_m", "baseline_vertical_m", "warning_mm", "alarm_mm", "rule", "n_window", "separability",
}
KEY = re.compile(r"\[[\"'](\w+)[\"']\]")


def row_key_lookups(root: Path) -> tuple[int, int]:
    """(lookups, files) of string subscripts naming a store column outside the store."""
    total, files = 0, 0
    for pkg in ("app", "projects"):
        for path in sorted((root / pkg).rglob("*.py")):
            if path.relative_to(root).as_posix() == "projects/store/campaign.py":
                continue
            n = sum(1 for m in KEY.finditer(path.read_text()) if m.group(1) in STORE_COLUMNS)
            total += n
            files += n > 0
    return total, files


STORE = "projects/store/"  # the store package is the one place that talks SQL
ROW_ACCESSORS = re.compile(r"\.(displacement_rows|plan_row|result_row|log_rows|reference_check_rows)\(|"
                           r"\b(series_rows|env_rows|json_rows)\(")


def store_leaks(root: Path) -> tuple[int, int, int]:
    """(files outside the store that run SQL, calls of row-returning accessors, stored plans decoded by hand)."""
    sql_files = accessors = plan_decodes = 0
    for pkg in ("app", "projects"):
        for path in (root / pkg).rglob("*.py"):
            if path.relative_to(root).as_posix().startswith(STORE):
                continue
            text = path.read_text()
            sql_files += bool(re.search(r"\.execute\(|\bc\.conn\b", text))
            accessors += len(ROW_ACCESSORS.findall(text))
            plan_decodes += len(re.findall(r"json\.loads\(\w+\[\"json\"\]\)", text))
    return sql_files, accessors, plan_decodes


def json_decodes(root: Path) -> int:
    n = 0
    for pkg in ("app", "projects"):
        for path in (root / pkg).rglob("*.py"):
            if path.relative_to(root).as_posix() != "projects/store/campaign.py":
                n += path.read_text().count("json.loads(")
    return n


def annotations(root: Path, pkg: str) -> tuple[int, int, int, int]:
    """(annotated params, params, fully annotated public functions, public functions)."""
    ann = params = full = public = 0
    for path in (root / pkg).rglob("*.py"):
        tree = ast.parse(path.read_text())
        for node in ast.walk(tree):
            if not isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                continue
            a = node.args
            args = [x for x in a.posonlyargs + a.args + a.kwonlyargs if x.arg not in ("self", "cls")]
            args += [x for x in (a.vararg, a.kwarg) if x is not None]
            k = sum(x.annotation is not None for x in args)
            ann += k
            params += len(args)
            if not node.name.startswith("_"):
                public += 1
                full += k == len(args) and node.returns is not None
    return ann, params, full, public


def main(argv: list[str]) -> int:
    import signal

    signal.signal(signal.SIGPIPE, signal.SIG_DFL)  # "| head" ends quietly
    root = Path(argv[1] if len(argv) > 1 else ".")
    n, f = row_key_lookups(root)
    print(f"row key lookups outside the store: {n} in {f} files")
    print(f"json.loads outside the store (app/, projects/): {json_decodes(root)}")
    sql, acc, plans = store_leaks(root)
    print(f"files outside the store running SQL: {sql}; calls returning SQL rows: {acc}; "
          f"stored plans decoded by hand: {plans}")
    tot = [0, 0, 0, 0]
    for pkg in PACKAGES:
        if not (root / pkg).is_dir():
            continue
        a, p, fu, pu = annotations(root, pkg)
        tot = [t + v for t, v in zip(tot, (a, p, fu, pu), strict=False)]
        print(f"{pkg:13s} annotated parameters {a}/{p} ({100 * a / max(p, 1):.0f} %), "
              f"fully annotated public functions {fu}/{pu} ({100 * fu / max(pu, 1):.0f} %)")
    a, p, fu, pu = tot
    print(f"{'all':13s} annotated parameters {a}/{p} ({100 * a / max(p, 1):.0f} %), "
          f"fully annotated public functions {fu}/{pu} ({100 * fu / max(pu, 1):.0f} %)")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
