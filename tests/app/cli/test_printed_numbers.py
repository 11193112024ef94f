"""Numbers printed with one precision per unit (issue 41 item 7): millimetres to 0.01 in tables, 0.001 in files,
never a float's 17 digits."""
import csv
import io
import json
import re

from app.cli.main import main


def test_millimetres_are_printed_with_one_precision(processed_copy, capsys):
    assert main(["limit", str(processed_copy), "--rule", "span:2375,1000"]) == 0  # 40 m / 2375 = 16.8421... mm
    capsys.readouterr()
    assert main(["status", str(processed_copy)]) == 0
    lines = capsys.readouterr().out.splitlines()
    head = lines.index("latest displacement of each measurement target:") + 1
    header = lines[head].split()
    for row in lines[head + 1:head + 6]:
        cells = dict(zip(header, row.split(), strict=False))
        for col in ("displacement_mm", "sigma_mm", "warning_mm", "alarm_mm"):
            assert re.fullmatch(r"-?\d+\.\d\d", cells[col]), (col, cells[col])
        assert cells["warning_mm"] == "16.84" and cells["alarm_mm"] == "40.00"
    assert main(["displacements", str(processed_copy), "--format", "csv"]) == 0
    rows = list(csv.DictReader(io.StringIO(capsys.readouterr().out)))
    for r in rows:
        for col, v in r.items():
            if col.endswith("_mm") and v:
                assert re.fullmatch(r"-?\d+(\.\d{1,3})?", v), (col, v)
    assert {r["warning_mm"] for r in rows} == {"16.842"}
    assert main(["displacements", str(processed_copy), "--format", "json"]) == 0
    assert {r["warning_mm"] for r in json.loads(capsys.readouterr().out)} == {16.842}
