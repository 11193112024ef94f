"""Target normals in layout.csv and the defaults when the layout has none."""
import numpy as np
import pytest

from common.errors import InputError
from lidar.layout import bridge_axis, layout_from_model, read_layout_csv, target_normals, write_layout_csv
from lidar.simulate import BridgeModel

HEADER = "id,group,x,y,z"


def _write(tmp_path, rows, extra=""):
    p = tmp_path / "layout.csv"
    p.write_text(HEADER + extra + "\n" + "\n".join(rows) + "\n")
    return p


ROWS = ["R1,reference,0,-1,2", "R2,reference,0,1,5", "R3,reference,40,1,2", "M1,measurement,8,-2,7",
        "M2,measurement,20,1,7", "M3,measurement,32,-2,7"]


def test_defaults_face_down_under_the_deck_and_into_the_span_on_piers(tmp_path):
    layout = read_layout_csv(_write(tmp_path, ROWS))
    n = target_normals(layout)
    assert np.allclose(n[3:], [0, 0, -1])
    assert np.allclose(n[:2], [[1, 0, 0], [1, 0, 0]], atol=0.02)  # pier 1 faces +x, toward the span
    assert np.allclose(n[2], [-1, 0, 0], atol=0.02)


def test_defaults_follow_a_bridge_axis_that_is_not_x(tmp_path):
    angle = np.radians(35.0)
    rot = np.array([[np.cos(angle), -np.sin(angle), 0], [np.sin(angle), np.cos(angle), 0], [0, 0, 1]])
    model = BridgeModel(span_m=25.0)
    lay = layout_from_model(model)
    from lidar.layout import Layout

    turned = Layout(lay.ids, lay.groups, lay.xyz @ rot.T, lay.diameters_m)
    assert abs(abs(bridge_axis(turned) @ rot[:, 0]) - 1) < 1e-6
    n = target_normals(turned)
    truth = np.array([t.normal for t in model.targets]) @ rot.T
    assert np.allclose(n, truth, atol=1e-6)


def test_given_normals_are_read_normalised_and_kept(tmp_path):
    rows = [r + ("," + ",".join(["0", "0", "-2"]) if r.startswith("M1") else ",,,") for r in ROWS]
    layout = read_layout_csv(_write(tmp_path, rows, ",nx,ny,nz"))
    assert np.allclose(layout.normals[3], [0, 0, -1])
    assert np.all(np.isnan(layout.normals[0]))
    out = tmp_path / "again.csv"
    write_layout_csv(layout, out)
    again = read_layout_csv(out)
    assert np.allclose(again.normals[3], [0, 0, -1]) and np.all(np.isnan(again.normals[0]))


@pytest.mark.parametrize("rows, extra, message", [
    ([r + ",1,0" for r in ROWS], ",nx,ny", "need all three columns"),
    ([r + ",a,0,1" for r in ROWS], ",nx,ny,nz", "must be numbers"),
    ([r + ",0,0,0" for r in ROWS], ",nx,ny,nz", "not zero"),
    ([r + ",nan,0,1" for r in ROWS], ",nx,ny,nz", "finite"),
])
def test_bad_normals_are_refused_naming_the_line(tmp_path, rows, extra, message):
    with pytest.raises(InputError, match=message) as err:
        read_layout_csv(_write(tmp_path, rows, extra))
    assert "layout.csv" in str(err.value)
