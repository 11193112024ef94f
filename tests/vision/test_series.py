"""Reading camera series files: columns, units, zones, gaps, NaNs and bad rows with line numbers."""
import numpy as np
import pytest

from common.errors import InputError, SurveyError
from vision.series import read_camera_series
from vision.simulate.series import simulate_series, write_series_csv

DAY = 86400 * 10 ** 9


def test_round_trip_of_a_simulated_file_with_zone_gap_and_nans(tmp_path):
    t, v = simulate_series(0, 3 * DAY, lambda t: np.sin(t / 1e13), outages=[(DAY, DAY + DAY // 4)],
                           nan_fraction=0.01)
    path = write_series_csv(tmp_path / "cam.csv", t, v, utc_offset_h=9)
    s = read_camera_series(path)
    assert np.array_equal(s.time_ns, t)
    assert np.allclose(s.values, v, atol=6e-4, equal_nan=True)
    assert s.n_missing == int(np.isnan(v).sum()) > 0
    assert len(s.gaps) == 1 and s.gaps[0][1] - s.gaps[0][0] == DAY // 4 + 60 * 10 ** 9
    assert s.sampling_s == 60.0 and s.n_bad == 0


def test_bad_rows_are_reported_with_their_line_numbers(tmp_path):
    lines = ["# comment", "time;deflection [cm];unit"] + \
            [f"2026-03-0{1 + k // 100}T{(k % 100) // 60:02d}:{k % 60:02d}:00;{k / 100:.2f};cm" for k in range(300)]
    lines[10] = "2026-13-40T00:00:00;1.0;cm"   # line 11: impossible date
    lines[20] = "2026-03-01T00:18:00;oops;cm"  # line 21: not a number
    lines[30] = "2026-03-01T00:28:00;1.0"      # line 31: a field short
    lines[40] = "2026-03-01T00:38:00;1.0;yards"  # line 41: unknown unit
    lines[50] = "2026-03-01T00:48:00;;cm"      # an empty reading: a gap value, not a bad row
    (tmp_path / "c.txt").write_text("\n".join(lines) + "\n")
    s = read_camera_series(tmp_path / "c.txt", positive="down")
    assert [b.line for b in s.bad_rows] == [11, 21, 31, 41]
    assert "not a date-time" in s.bad_rows[0].reason and "not a number" in s.bad_rows[1].reason
    assert "fields" in s.bad_rows[2].reason and "unit" in s.bad_rows[3].reason
    assert s.n_missing == 1 and len(s) == 300 - 4
    assert s.values[5] == pytest.approx(-0.5 * 10 * 0.01 * 10)  # 0.05 cm down -> -0.5 mm
    assert s.summary()["first_bad_lines"][0].startswith("line 11")


def test_timezone_column_date_and_time_columns_and_unix_seconds(tmp_path):
    (tmp_path / "tz.csv").write_text("date,time,tz,disp_mm\n2026-01-01,09:00,+09:00,1\n2026-01-01,01:00,UTC,2\n"
                                     "2026-01-01,02:00,Europe/Berlin,3\n")
    s = read_camera_series(tmp_path / "tz.csv")
    base = np.datetime64("2026-01-01T00:00", "ns").astype(np.int64)
    assert list(s.time_ns) == [base, base + 3600 * 10 ** 9]  # 02:00 in Berlin is 01:00 UTC: a repeated time
    assert s.n_duplicates == 1 and list(s.values) == [1.0, 2.0]
    (tmp_path / "unix.txt").write_text("unix value\n1767225600 0.5\n1767225660 0.6\n")
    u = read_camera_series(tmp_path / "unix.txt", unit="m")
    assert u.time_ns[0] == 1767225600 * 10 ** 9 and u.values[1] == pytest.approx(600.0)


def test_naive_times_take_the_given_zone(tmp_path):
    (tmp_path / "n.csv").write_text("timestamp,displacement\n2026-01-01 09:00:00,1\n2026-01-01 09:01:00,2\n")
    s = read_camera_series(tmp_path / "n.csv", timezone="Asia/Seoul")
    assert s.time_ns[0] == np.datetime64("2026-01-01T00:00", "ns").astype(np.int64)


@pytest.mark.parametrize("content, message", [
    ("", "no data rows"),
    ("1,2\n3,4\n", "no header"),
    ("time,a,b\n2026-01-01,1,2\n", "cannot tell which column"),
    ("a,b\n1,2\n", "no time column"),
    ("time,disp\n" + "x,1\n" * 20, "no readable rows"),
])
def test_unreadable_files_are_refused_with_one_line(tmp_path, content, message):
    p = tmp_path / "bad.csv"
    p.write_text(content)
    with pytest.raises(SurveyError, match=message) as e:
        read_camera_series(p)
    assert str(p) in str(e.value) and "\n" not in str(e.value)


def test_binary_and_missing_files(tmp_path):
    (tmp_path / "b.csv").write_bytes(b"\xff\xfe\x00\x81\x00garbage")
    with pytest.raises(SurveyError, match="not a text file"):
        read_camera_series(tmp_path / "b.csv")
    with pytest.raises(InputError, match="no such file"):
        read_camera_series(tmp_path / "none.csv")
