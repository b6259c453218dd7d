"""Measured data files: every mistake is one clear error naming the file, line or column."""
import numpy as np
import pytest

from mcl.data import TimeSeries, read_csv, write_csv
from mcl.errors import DataError


def csv(tmp_path, text):
    f = tmp_path / "d.csv"
    f.write_text(text)
    return f


def test_round_trip(tmp_path):
    ts = TimeSeries(np.array([0.0, 0.5, 1.0]), np.array([[1.0, 2.0], [3.0, 4.0], [5.0, 6.5]]), ["u", "y"])
    write_csv(tmp_path / "x.csv", ts)
    back = read_csv(tmp_path / "x.csv")
    assert back.names == ["u", "y"] and np.array_equal(back.values, ts.values)


@pytest.mark.parametrize("text,message,line", [
    ("t,u\n0,1\n1,2\n", "first column must be 'time'", 1),
    ("time,u\n0,1\n1,abc\n", "'abc' is not a number", 3),
    ("time,u\n0,1\n1,2,3\n", "3 fields", 3),
    ("time,u,u\n0,1,1\n1,2,2\n", "duplicate column", 1),
])
def test_malformed_files_name_the_line(tmp_path, text, message, line):
    f = csv(tmp_path, text)
    with pytest.raises(DataError, match=message) as err:
        read_csv(f)
    assert err.value.where == f"{f}:{line}"


@pytest.mark.parametrize("text,message", [
    ("time,u\n0,1\n1,nan\n", "column 'u': 'nan' is not a measured value"),
    ("time,u\n0,1\n1,inf\n", "'inf' is not a measured value"),
    ("time,u\n0,\n1,\n", "column 'u' has no measured value"),
    ("time,u\n,1\n1,2\n", "time is not a finite number"),
    ("time,u\n0,1\n0,2\n", "not strictly increasing at data row 2"),
    ("time,u\n0,1\n", "at least two samples"),
])
def test_bad_values(tmp_path, text, message):
    with pytest.raises(DataError, match=message):
        read_csv(csv(tmp_path, text))


@pytest.mark.parametrize("text", ["time;u;y\n0;1,5;2\n0,25;2;-3,5e-1\n",       # a European spreadsheet's
                                  "time\tu\ty\n0\t1.5\t2\n0.25\t2\t-0.35\n",
                                  "time,u,y,\n0,1.5,2,\n0.25,2,-0.35,\n",      # each line ending in a delimiter
                                  "time;u;y;;\n0;1,5;2;;\n0,25;2;-0,35;;\n"])
def test_semicolon_and_tab_separated_files_are_read(tmp_path, text):
    ts = read_csv(csv(tmp_path, text))
    assert ts.names == ["u", "y"] and ts.time.tolist() == [0.0, 0.25]
    assert ts.values.tolist() == [[1.5, 2.0], [2.0, -0.35]]


def test_missing_columns_are_listed(tmp_path):
    ts = read_csv(csv(tmp_path, "time,a\n0,1\n1,2\n"))
    with pytest.raises(DataError, match="missing column.* u, T_amb; the file has: a"):
        ts.select(["u", "T_amb"])


def test_blank_cells_are_values_not_measured(tmp_path):
    ts = read_csv(csv(tmp_path, "time,u,y\n0,1,2\n1,2,\n2,3,4\n3,4,\n"))
    assert ts.measured()[:, 1].tolist() == [True, False, True, False]
    assert np.allclose(ts.filled().column("y"), [2, 3, 4, 4])
