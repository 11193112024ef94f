"""The ``scanners`` command: the scanner catalogue, what each instrument offers and where each value came from."""
from __future__ import annotations

from app.cli.output import dump_json, table
from lidar.scanner_catalogue import CATALOGUE, get_scanner


def cmd_scanners(args) -> int:
    if args.name is None:
        rows = [{"name": p.name, "kind": p.kind, "rate_pts_s": int(p.pulse_rate_hz),
                 "range_noise_mm": p.range_noise_m * 1000, "windows": "yes" if p.windowed else "full dome only",
                 "resolutions": ", ".join(lab for lab, _ in p.step_presets) or
                 f"free, >= {p.min_theta_step_deg:g}/{p.min_phi_step_deg:g} deg"} for p in CATALOGUE.values()]
        if args.json:
            dump_json([p.to_dict() for p in CATALOGUE.values()])
        else:
            table(rows, ["name", "kind", "rate_pts_s", "range_noise_mm", "windows", "resolutions"])
        return 0
    prof = get_scanner(args.name)
    if args.json:
        dump_json(prof.to_dict())
        return 0
    src = dict(prof.sources)
    if prof.step_presets:
        for k in ("min_theta_step_deg", "min_phi_step_deg"):
            src.setdefault(k, "the finest preset")
    for k in ("horizontal_direction", "horizontal_zero_deg", "vertical_reference"):
        if "angles" in src:
            src.setdefault(k, src["angles"])
    src.setdefault("max_tilt_deg", "assumed: a levelled set-up; 2 deg leaves room for the layout's errors")
    d = prof.to_dict()

    def shown(k, v):
        if k == "step_presets":
            labels = [x["label"] for x in v]
            return f"{len(labels)}: {labels[0]} ... {labels[-1]}" if len(labels) > 2 else ", ".join(labels) or "-"
        return ", ".join(str(x) for x in v) if isinstance(v, list) else v
    rows = [{"field": k, "value": shown(k, v), "source": src.get(k, "")} for k, v in d.items()
            if k not in ("sources", "notes")]
    table(rows, ["field", "value", "source"])
    print(f"angles: {prof.angle_convention()} ({src.get('angles', '')})")
    if prof.notes:
        print(prof.notes)
    return 0
