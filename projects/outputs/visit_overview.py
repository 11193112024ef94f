"""A visit of several set-ups as the surveyor works it: set-up by set-up, in order, with what each one measures.

The set-ups' plans are made together (:mod:`lidar.visit_plan`); each stored plan's JSON carries the visit's summary
(its share of the budget, its tie targets, the targets another set-up measures instead). These lines are what
``plan`` and ``field-sheet`` show of the whole visit.
"""
from __future__ import annotations

from collections.abc import Mapping

from lidar.plan import ScanPlan


def _ids(ids) -> str:
    return ", ".join(sorted(ids, key=lambda t: (t.rstrip("0123456789"), int(t[len(t.rstrip("0123456789")):] or 0))))


def visit_overview(plans: Mapping[int, ScanPlan], summaries: Mapping[int, Mapping]) -> list[str]:
    """Lines describing a visit's set-ups in the order to work them.

    Parameters
    ----------
    plans : mapping set-up -> ScanPlan
        Every set-up's plan.
    summaries : mapping set-up -> dict
        Each plan JSON's ``visit`` entry (empty when the set-up was planned alone).

    Returns
    -------
    list of str
        One heading line, then one line per set-up (empty for a visit of one set-up).
    """
    if len(plans) < 2:
        return []
    together = all(summaries.get(k) for k in plans)
    order = sorted(plans, key=lambda k: (summaries.get(k, {}).get("position_in_order", k), k))
    total = sum(p.total_seconds for p in plans.values())
    if together:
        budget = float(next(iter(summaries.values()))["visit_budget_seconds"])
        head = (f"the visit's {len(plans)} set-ups, planned together: {total / 60:.1f} min of fine scans against the "
                f"visit's budget of {budget / 60:.0f} min; work them in this order (set-up {order[0]} is the frame "
                "the others are joined into):")
    else:
        head = (f"the visit's {len(plans)} set-ups, each planned as if it were alone ('settings plan_together' is "
                f"false): {total / 60:.1f} min of fine scans in all; work them in this order:")
    lines = [head]
    for n, k in enumerate(order, start=1):
        plan, doc = plans[k], summaries.get(k, {})
        closure = next((r.reflector for r in plan.rois if r.closure), None)
        windows = [r for r in plan.rois if not r.closure]
        deck = [r.reflector for r in windows if r.group == "measurement"]
        parts = [f"{n}. set-up {k}: {len(windows)} windows + closure ({closure}) last" if closure else
                 f"{n}. set-up {k}: {len(windows)} windows",
                 f"{plan.total_seconds / 60:.1f} min" + (f" of its share {plan.budget_seconds / 60:.1f} min"
                                                         if together else ""),
                 f"deck targets {_ids(deck) or 'none'}"]
        if doc.get("second_sightings"):
            parts.append(f"in the time left, a second sighting of {_ids(doc['second_sightings'])}")
        if doc.get("ties"):
            parts.append(f"joined to the set-ups before it by {_ids(doc['ties'])}")
        elsewhere: dict[int, list[str]] = {}
        for t, j in doc.get("measured_elsewhere", {}).items():
            elsewhere.setdefault(int(j), []).append(t)
        parts += [f"{_ids(ts)} measured from set-up {j}" for j, ts in sorted(elsewhere.items())]
        lines.append("; ".join(parts))
    for w in (next(iter(summaries.values()), {}) or {}).get("warnings", []):
        lines.append(f"warning: {w}")
    return lines
