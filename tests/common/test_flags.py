"""The flag registry: every flag the product raises is declared once, and nothing else is a flag."""
from __future__ import annotations

import ast
from pathlib import Path

import numpy as np
import pytest

from common import flags
from common.flags import REGISTRY, UnknownFlagError

ROOT = Path(__file__).resolve().parents[2]
PACKAGES = ("app", "common", "lidar", "projects", "registration", "vision")


def _literal_codes(path: Path) -> list[tuple[int, str]]:
    """String literals in ``path`` equal to a registered code, other than dict keys and subscripts."""
    tree = ast.parse(path.read_text())
    skip: set[int] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Dict):
            skip.update(id(k) for k in node.keys if k is not None)
        elif isinstance(node, ast.Subscript):
            skip.add(id(node.slice))
        elif isinstance(node, ast.Call) and getattr(node.func, "attr", None) in ("get", "pop", "setdefault"):
            skip.update(id(a) for a in node.args[:1])
        elif isinstance(node, ast.Set) and all(isinstance(e, ast.Constant) for e in node.elts):
            skip.update(id(e) for e in node.elts)  # a set of field names (keys of a stored document)
    out = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Constant) and isinstance(node.value, str) and id(node) not in skip:
            if node.value in REGISTRY or node.value in flags.RENAMED:
                out.append((node.lineno, node.value))
    return out


def test_no_flag_code_is_written_as_a_literal_outside_the_registry():
    offenders = []
    for pkg in PACKAGES:
        for path in sorted((ROOT / pkg).rglob("*.py")):
            if path == ROOT / "common" / "flags.py":
                continue
            offenders += [f"{path.relative_to(ROOT)}:{line}: {code!r}" for line, code in _literal_codes(path)]
    assert not offenders, "flag codes as literals (import the constant from common.flags):\n" + "\n".join(offenders)


def test_every_flag_has_a_severity_meaning_and_producer():
    for f in REGISTRY.values():
        assert f.severity in flags.SEVERITIES
        assert f.meaning and "\n" not in f.meaning
        assert f.code == f.code.lower() and "-" not in f.code
        module = f.raised_by
        assert (ROOT / Path(*module.split("."))).with_suffix(".py").exists() or (ROOT / Path(*module.split("."))).is_dir()


def test_an_unknown_code_is_an_error_not_a_guess():
    with pytest.raises(UnknownFlagError, match="unknown flag 'spurious_code'"):
        flags.severity("spurious_code: with a reason")
    with pytest.raises(UnknownFlagError):
        flags.worst(["missing", "renamed-in-a-future-version"])
    assert flags.severity("deck_not_measured: 0 of 6 found") == flags.PROBLEM


def test_older_codes_are_mapped_by_the_migration():
    import sqlite3

    from projects.store import schema

    conn = sqlite3.connect(":memory:")
    schema.create(conn)
    conn.execute("INSERT INTO camera_series(name, reflector, sha256, stored_path, original_path, imported, options, "
                 "summary, arrays) VALUES ('s', NULL, 'x', 'p', 'o', 'i', '{}', '{}', x'00')")
    conn.execute("""INSERT INTO crossvals(series, summary, created)
                    VALUES ('s', '{"pairs": [{"flags": ["no-camera-data"]}]}', 'now')""")
    conn.executescript(schema.MIGRATIONS[8])
    summary = conn.execute("SELECT summary FROM crossvals").fetchone()[0]
    assert '"no_camera_data"' in summary and "no-camera-data" not in summary
    for old, new in flags.RENAMED.items():
        assert new in REGISTRY and flags.renamed(old + ": why") == new + ": why"


@pytest.mark.slow
def test_every_flag_the_trap_simulations_raise_is_registered():
    """The simulator's traps (cable tie, occlusion, a removed and a moved target, saturation) end in registered flags."""
    from common.series import Series
    from lidar.displacement import compute_displacements
    from lidar.simulate import EpochConditions
    from lidar.simulate.epochs import GROUPS, LAB_POSITIONS, fine_epoch
    from vision.crossval import cross_validate

    base, _, _, _ = fine_epoch(EpochConditions(), LAB_POSITIONS[0], seed=1, min_points=300)
    traps = [EpochConditions(cable_ties=("R1",)), EpochConditions(occluded=("M2",)),
             EpochConditions(removed=("M3", "R2")), EpochConditions(moved_targets={"R4": (0.0, 0.0, 0.006)}),
             EpochConditions(saturated=True), EpochConditions(removed=("M1", "M2", "M3", "M4"))]
    seen: set[str] = set()
    for k, cond in enumerate(traps):
        cents, _, _, _ = fine_epoch(cond, LAB_POSITIONS[k % 3], seed=10 + k, min_points=300)
        for c in cents.values():
            seen.update(c.flags)
        try:
            res = compute_displacements(base, cents, GROUPS)
        except Exception as exc:  # a refusal is an error, not a flag
            assert "deck plane" in str(exc) or "reference" in str(exc)
            continue
        seen.update(res.flags)
        for d in res.displacements:
            seen.update(d.flags)
    day = 86_400_000_000_000
    cam = Series(np.array([0, 1, 2, 10], dtype=np.int64) * day, np.array([0.0, 0.1, 0.2, 0.3]), "mm")
    cv = cross_validate(["a", "b", "c", "d"], np.array([0, 1, 5, 10], dtype=np.int64) * day,
                        np.array([0.0, np.nan, 0.2, 0.3]), np.full(4, 0.1), cam)
    for p in cv.pairs:
        seen.update(p.flags)
    assert {"second_bright_object", "reference_moved", "missing", "no_camera_data"} <= seen, seen
    for f in seen:
        flags.lookup(f)  # raises UnknownFlagError for an unregistered code


def test_every_warning_and_problem_says_what_to_do_and_no_information_asks_for_anything():
    """Severity by consequence: a warning or a problem is something the surveyor acts on, so it names the act;
    information (a doubt the sigma carries) asks for nothing."""
    for f in REGISTRY.values():
        if f.severity == flags.INFO:
            assert not f.action, f.code
        else:
            assert len(f.action) > 10 and "\n" not in f.action, f.code
        assert f.words and "_" not in f.words, f.code
