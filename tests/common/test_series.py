"""The one series reader (issue 41 item 6): separators told by the header, decimal commas, bad rows left out and
counted (never a refusal while rows are left), --column, and the zone every import assumed."""
import numpy as np
import pytest

from common.errors import SurveyError
from common.series import Quantity, read_series, series_arrays_from_npz, series_npz_bytes, sniff_separator

HUMIDITY = Quantity("relative humidity", ("humidity", "rh"), {"%": (1.0, 0.0), "pct": (1.0, 0.0)}, "%", "%",
                    signed=False)
TEMPERATURE = Quantity("air temperature", ("temperature", "temp"), {"degc": (1.0, 0.0)}, "degc", "°C", signed=False)


def test_a_humidity_file_with_one_bad_row_is_read_and_the_row_counted(tmp_path):
    rows = ["time,humidity_pct"] + [f"2026-03-01T{h:02d}:00,{60 + h}" for h in range(24)]
    rows.insert(4, "2026-03-01T03:30,61,extra")  # a row with a field too many, among the first lines
    rows.insert(9, "sensor reset")                # and one with none
    (tmp_path / "rh.csv").write_text("\n".join(rows) + "\n")
    s = read_series(tmp_path / "rh.csv", quantity=HUMIDITY)
    assert len(s) == 24 and s.n_bad == 2 and s.n_rows == 26 and s.column == "humidity_pct"
    assert [b.line for b in s.bad_rows] == [5, 10]
    assert s.bad_rows[0].reason == "3 fields where the header has 2 fields"
    assert "2 of 26 rows could not be read" in s.notes[0]
    assert s.values[0] == 60.0 and s.unit == "%" and s.unit_read == "pct"
    named = read_series(tmp_path / "rh.csv", quantity=HUMIDITY, column="humidity_pct")
    assert np.array_equal(named.values, s.values)
    with pytest.raises(SurveyError, match=r"no column 'rh'; the columns are time, humidity_pct$"):
        read_series(tmp_path / "rh.csv", quantity=HUMIDITY, column="rh")


@pytest.mark.parametrize("sep", [";", "\t", " "])
def test_decimal_commas_in_files_not_separated_by_commas(tmp_path, sep):
    rows = [f"time{sep}temperature"] + [f"2026-03-01T{h:02d}:00{sep}{h},5" for h in range(24)]
    (tmp_path / "t.txt").write_text("\n".join(rows) + "\n")
    s = read_series(tmp_path / "t.txt", quantity=TEMPERATURE)
    assert s.n_bad == 0 and len(s) == 24 and s.values[3] == 3.5


def test_the_header_tells_the_separator():
    assert sniff_separator(["time;temp", "2026-03-01T00:00;12,5", "2026-03-01T01:00;13,0"]) == ";"
    assert sniff_separator(["time,temp", "2026-03-01T00:00,12", "garbage;;;", "2026-03-01T01:00,13"]) == ","
    assert sniff_separator(["time temp", "2026-03-01T00:00 12"]) is None


def test_every_series_says_which_zone_it_assumed(tmp_path):
    (tmp_path / "naive.csv").write_text("time,temperature\n2026-03-01 09:00,1\n2026-03-01 10:00,2\n")
    s = read_series(tmp_path / "naive.csv", quantity=TEMPERATURE, timezone="Europe/Berlin")
    assert s.times_read == "without an offset, read as Europe/Berlin time"
    assert s.time_ns[0] == np.datetime64("2026-03-01T08:00", "ns").astype(np.int64)
    (tmp_path / "aware.csv").write_text("time,temperature\n2026-03-01T09:00+01:00,1\n2026-03-01T10:00+01:00,2\n")
    a = read_series(tmp_path / "aware.csv", quantity=TEMPERATURE, timezone="Asia/Seoul")
    assert a.times_read == "with their UTC offsets" and a.time_ns[0] == s.time_ns[0]
    assert a.summary()["times"] == "with their UTC offsets"


def test_only_a_file_with_no_readable_row_is_refused(tmp_path):
    (tmp_path / "half.csv").write_text("time,temperature\n" + "2026-03-01T00:00,1\n" * 1 +
                                       "".join(f"bad{k},1\n" for k in range(9)))
    s = read_series(tmp_path / "half.csv", quantity=TEMPERATURE)
    assert len(s) == 1 and s.n_bad == 9
    (tmp_path / "none.csv").write_text("time,temperature\nx,1\ny,2\n")
    with pytest.raises(SurveyError, match="no readable rows"):
        read_series(tmp_path / "none.csv", quantity=TEMPERATURE)


def test_stored_arrays_name_their_values_and_read_the_first_format(tmp_path):
    import io

    t, v = np.array([1, 2], np.int64), np.array([20.5, np.nan])
    t2, v2 = series_arrays_from_npz(series_npz_bytes(t, v))
    assert list(t2) == [1, 2] and v2[0] == 20.5 and np.isnan(v2[1])
    buf = io.BytesIO()
    np.savez(buf, version=np.int64(1), time_ns=t, value_mm=v)  # as stored before version 2
    t1, v1 = series_arrays_from_npz(buf.getvalue())
    assert list(t1) == [1, 2] and v1[0] == 20.5
    buf = io.BytesIO()
    np.savez(buf, version=np.int64(99), time_ns=t, values=v)  # written by a later version
    with pytest.raises(SurveyError, match="newer"):
        series_arrays_from_npz(buf.getvalue())
