"""The action log in words: every logged action a phrase, an unknown one its details as pairs, never raw JSON."""
from projects.outputs.report.action_log import action_row
from projects.store.records import LogEntry


def test_known_actions_read_as_words():
    row = action_row(LogEntry(1, "2026-12-01T19:54:39+00:00", "import", "2026-01-05",
                              {"role": "coarse", "files": ["/x/field/2026-01-05/coarse.laz"], "sha256": ["35543d52a3f7f9e8"
                                                                                                          "852356df6a8"]}))
    assert (row.time, row.epoch, row.action, row.files) == ("2026-12-01 19:54:39", "2026-01-05", "coarse scan imported",
                                                            "coarse.laz")
    assert row.result.startswith("stored read-only, SHA-256 35543d52a3f7") and "/x/field" not in row.result
    lim = action_row(LogEntry(2, "2026-12-01T19:54:37+00:00", "limit", None, {"reflector": "*", "rule": "kr-rail:0-200"}))
    assert lim.result == "every measurement target: kr-rail:0-200" and lim.epoch == ""
    cv = action_row(LogEntry(3, "t", "crossval", None, {"series": "cam", "reflector": "M3", "n_pairs": 1,
                                                        "bias_mm": None, "rmse_mm": None}))
    assert "1 pair," in cv.result and "RMSE – mm" in cv.result
    cv = action_row(LogEntry(3, "t", "crossval", None, {"series": "cam", "reflector": "M3", "n_pairs": 51,
                                                        "bias_mm": -0.0037, "rmse_mm": 0.0938}))
    assert "51 pairs, bias +0.00 mm, RMSE 0.09 mm" in cv.result


def test_unknown_or_older_actions_show_their_details_as_pairs():
    row = action_row(LogEntry(4, "2026-12-01T10:00:00+00:00", "repair", None,
                              {"file": "/a/b/scan.laz", "re_registered": 2, "ratio": 0.333333333}))
    assert row.action == "repair" and row.files == "scan.laz"
    assert row.result == "re registered: 2; ratio: 0.3333" and "{" not in row.result
    odd = action_row(LogEntry(5, "t", "import", "e1", {"role": "fine", "files": 7}))  # details of another shape
    assert "{" not in odd.result and odd.action
