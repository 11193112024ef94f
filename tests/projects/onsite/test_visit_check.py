"""The check of a whole visit: a target one set-up missed is no re-scan when another measured it, unless the join
needs it."""
from projects.onsite.check import EpochCheck, TargetCheck, visit_verdict


def _row(tid: str, status: str = "ok") -> TargetCheck:
    found = status != "not found"
    return TargetCheck(tid, "reference" if tid.startswith("R") else "measurement", found, 1000 if found else 0, 1000,
                       0.05 if found else float("nan"), 0.07, status)


def _check(*rows: TargetCheck) -> EpochCheck:
    return EpochCheck("v1", tuple(rows), None)


def test_a_target_missed_by_one_set_up_and_measured_by_the_other_is_not_a_rescan():
    one = _check(_row("R1"), _row("R2"), _row("R3"), _row("M1"), _row("M9", "not found"))
    two = _check(_row("R1"), _row("R2"), _row("R3"), _row("M9"), _row("M12", "short"))
    v = visit_verdict("v1", {1: one, 2: two})
    assert v.covered == {"M9": 2}
    assert dict(v.rescan[2]) == {"M12": "short"} and not v.rescan[1]
    assert not v.ok and v.to_json()["rescan"] == {"2": {"M12": "short"}}


def test_every_target_measured_by_one_set_up_or_another_completes_the_visit():
    one = _check(_row("R1"), _row("R2"), _row("R3"), _row("M1"), _row("M2", "imprecise"))
    two = _check(_row("R1"), _row("R2"), _row("R3"), _row("M2"), _row("M1", "short"))
    v = visit_verdict("v1", {1: one, 2: two})
    assert v.ok and v.covered == {"M1": 1, "M2": 2}


def test_a_tie_the_join_needs_is_a_rescan_even_when_the_other_set_up_measured_it():
    one = _check(_row("R1"), _row("R2"), _row("R3", "not found"), _row("M1"))
    two = _check(_row("R1"), _row("R2"), _row("R3"), _row("M5"))
    v = visit_verdict("v1", {1: one, 2: two})
    assert list(v.rescan[1]) == ["R3"] and "the join needs it" in v.rescan[1]["R3"]
    assert "R3" not in v.covered and not v.ok
