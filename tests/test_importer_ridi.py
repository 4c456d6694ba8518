"""RIDI processed tables (core.importers.ridi): synthetic CSV and .xlsx files written by the test, never the data."""

import zipfile

import numpy as np
import pytest

from core.importers import RIDI, detect_format, load_recording
from core.importers.ridi import read_ridi
from core.recording import RecordingError

HEADER = ["", "time", "gyro_x", "gyro_y", "gyro_z", "acce_x", "acce_y", "acce_z", "magnet_x", "magnet_y", "magnet_z",
          "pos_x", "pos_y", "pos_z", "ori_w", "Distance Error"]


def _table(n=250, seed=5):
    rng = np.random.default_rng(seed)
    t = 86672.13 + np.arange(n) / 200.0
    v = rng.normal(size=(n, len(HEADER) - 2))
    v[:, 3:6] += [0.0, 9.8, 0.6]  # upright phone: gravity on y
    return np.column_stack([np.arange(n), t, v])


def _col(j):
    s = ""
    j += 1
    while j:
        j, r = divmod(j - 1, 26)
        s = chr(65 + r) + s
    return s


def _write_csv(path, table, header=HEADER):
    path.write_text(",".join(header) + "\n" + "".join(",".join(f"{x:.17g}" for x in r) + "\n" for r in table))


def _write_xlsx(path, table, shared=False, header=HEADER):
    ns = "http://schemas.openxmlformats.org/spreadsheetml/2006/main"
    strings = [h for h in header if h]
    head = "".join(
        (f'<c r="{_col(j)}1" t="s"><v>{strings.index(h)}</v></c>' if shared else
         f'<c r="{_col(j)}1" t="inlineStr"><is><t>{h}</t></is></c>') for j, h in enumerate(header) if h)
    body = "".join(f'<row r="{i + 2}">' + "".join(f'<c r="{_col(j)}{i + 2}" t="n"><v>{x:.17g}</v></c>'
                                                  for j, x in enumerate(row)) + "</row>" for i, row in enumerate(table))
    with zipfile.ZipFile(path, "w") as z:
        z.writestr("xl/worksheets/sheet1.xml", f'<worksheet xmlns="{ns}"><sheetData><row r="1">{head}</row>{body}'
                                               "</sheetData></worksheet>")
        if shared:
            z.writestr("xl/sharedStrings.xml", f'<sst xmlns="{ns}">' + "".join(f"<si><t>{s}</t></si>" for s in strings)
                       + "</sst>")


@pytest.mark.parametrize("form", ["csv", "xlsx", "xlsx-shared"])
def test_ridi_round_trip(tmp_path, form):
    table = _table()
    path = tmp_path / ("data.csv" if form == "csv" else "seq.xlsx")
    if form == "csv":
        _write_csv(path, table)
    else:
        _write_xlsx(path, table, shared=form.endswith("shared"))
    rec = read_ridi(str(path), warn=False)
    assert np.array_equal(rec.streams["acc"].t_ns, np.round(table[:, 1] * 1e9).astype(np.int64))
    assert np.allclose(rec.streams["gyro"].values, table[:, 2:5])
    assert np.allclose(rec.streams["acc"].values, table[:, 5:8])
    assert np.allclose(rec.streams["mag"].values, table[:, 8:11])
    assert np.allclose(rec.streams["posi"].values, table[:, 11:14])
    assert abs(rec.streams["acc"].rate_hz - 200.0) < 1.0
    assert "truth_attitude" not in rec.streams  # ori_w alone: no attitude


def test_ridi_reads_the_tango_orientation_as_the_truth_attitude(tmp_path):
    """``ori_w, ori_x, ori_y, ori_z`` (the Tango pose, device -> Tango frame) become ``truth_attitude`` (w, x, y, z):
    the true heading of the device's axes in the frame of ``posi`` (issue #25, h13/bagsign)."""
    header = HEADER[:-2] + ["ori_w", "ori_x", "ori_y", "ori_z"]
    table = _table()
    q = np.random.default_rng(2).normal(size=(len(table), 4))
    table = np.column_stack([table[:, :len(HEADER) - 2], q / np.linalg.norm(q, axis=1, keepdims=True)])
    table[5, 14:18] *= 1.5  # a row that is not a unit quaternion is not an attitude: dropped, as OxIOD's
    path = tmp_path / "data.csv"
    _write_csv(path, table, header)
    rec = read_ridi(str(path), warn=False)
    assert rec.streams["truth_attitude"].columns == ("w", "x", "y", "z")
    assert np.allclose(rec.streams["truth_attitude"].values, np.delete(table[:, 14:18], 5, axis=0))
    assert not any(c.startswith("ori_") for c in rec.metadata["columns_ignored"])


def test_ridi_data_csv_in_nanoseconds_and_a_last_line_without_its_newline(tmp_path):
    """RIDI's own processed/data.csv keeps the sensor clock in ns (the .xlsx copies in s); a complete last line
    without a newline is a row, a cut one is skipped and said."""
    table = _table(n=400)
    ns = table.copy()
    ns[:, 1] = np.round(table[:, 1] * 1e9)
    path = tmp_path / "data.csv"
    _write_csv(path, ns)
    path.write_text(path.read_text().rstrip("\n"))  # no newline after the last row
    rec = read_ridi(str(path), warn=False)
    assert len(rec.streams["acc"].t_ns) == 400
    assert np.array_equal(rec.streams["acc"].t_ns, ns[:, 1].astype(np.int64))
    assert abs(rec.streams["acc"].rate_hz - 200.0) < 1.0 and "ns" in rec.metadata["time_base"]
    text = path.read_text()
    path.write_text(text[:text.rfind(",")])  # the last line cut inside its fields
    rec = read_ridi(str(path), warn=False)
    assert len(rec.streams["acc"].t_ns) == 399 and any("cut off" in r for r in rec.repairs)


def test_ridi_refuses_a_table_without_its_columns(tmp_path):
    p = tmp_path / "other.csv"
    p.write_text("time,x,y,z\n0,1,2,3\n")
    with pytest.raises(RecordingError, match="acce_x"):
        read_ridi(str(p), warn=False)


@pytest.mark.parametrize("form", ["csv", "xlsx"])
def test_ridi_is_detected_as_a_file_or_its_folder(tmp_path, form):
    # fails before the wiring: detect_format did not know the table (csv) or the workbook (xlsx: "zip archive")
    folder = tmp_path / "processed"
    folder.mkdir()
    table = _table(n=120)
    path = folder / ("data.csv" if form == "csv" else "seq.xlsx")
    _write_csv(path, table) if form == "csv" else _write_xlsx(path, table)
    assert detect_format(str(path)) == RIDI and detect_format(str(folder)) == RIDI
    rec = load_recording(str(folder), warn=False)
    assert rec.metadata["source_format"] == RIDI and np.allclose(rec.streams["posi"].values, table[:, 11:14])


@pytest.mark.parametrize("form", ["csv", "xlsx"])
def test_ridi_half_matches_name_what_is_missing(tmp_path, form):
    table = _table(n=20)
    header = ["", "t", *HEADER[2:]]  # "time" renamed: RIDI's sensor columns without its time
    path = tmp_path / ("data.csv" if form == "csv" else "seq.xlsx")
    _write_csv(path, table, header) if form == "csv" else _write_xlsx(path, table, header=header)
    with pytest.raises(RecordingError, match=r"without its column\(s\) time|lacks RIDI's time"):
        detect_format(str(path))
    if form == "xlsx":  # a workbook of other columns is said to be one
        _write_xlsx(path, table, header=["", "a", "b", "c", "d", "e", "f", "g", "h", "i", "j", "k", "l", "m", "n",
                                         "o"])
        with pytest.raises(RecordingError, match="an Excel workbook without RIDI's columns"):
            detect_format(str(path))
        with zipfile.ZipFile(path, "w") as z:  # a worksheet cut short: one clean error, not the XML parser's
            z.writestr("xl/worksheets/sheet1.xml", '<worksheet><sheetData><row r="1"><c r="A1" t="s">')
        with pytest.raises(RecordingError, match="damaged .xlsx worksheet"):
            detect_format(str(path))
        with pytest.raises(RecordingError, match="damaged .xlsx worksheet"):
            read_ridi(str(path), warn=False)


def test_ridi_csv_acceleration_unit_check_and_bad_lines(tmp_path):
    # fails before the change: acceleration in g was kept as it was (read as m/s^2, a ninth of gravity)
    table = _table(n=300)
    g = table.copy()
    g[:, 5:8] /= 9.80665
    path = tmp_path / "data.csv"
    _write_csv(path, g)
    lines = path.read_text().splitlines(True)
    lines[20] = lines[20].replace(lines[20].split(",")[6], "oops", 1)  # acce_x not a number: a bad line
    lines.insert(40, "\n")  # a blank line is not a line of data (the line numbers after it move)
    path.write_text("".join(lines))
    rec = read_ridi(str(path), warn=False)
    assert np.allclose(rec.streams["acc"].values, np.delete(table[:, 5:8], 19, axis=0), rtol=1e-9)
    assert any("values are in g" in r for r in rec.repairs)
    assert any("skipped 1 bad line(s) of 300 (first: line 21" in r for r in rec.repairs)
    assert len(rec.streams["gyro"].t_ns) == 299


@pytest.mark.parametrize("form", ["csv.gz", "xlsx"])
def test_ridi_size_limit_holds(tmp_path, form):
    import gzip

    path = tmp_path / ("data.csv" if form == "csv.gz" else "seq.xlsx")
    _write_csv(path, _table(n=50)) if form == "csv.gz" else _write_xlsx(path, _table(n=50))
    if form == "csv.gz":
        path = tmp_path / "data.csv.gz"
        path.write_bytes(gzip.compress((tmp_path / "data.csv").read_bytes()))
    assert len(read_ridi(str(path), warn=False).streams["acc"].t_ns) == 50
    with pytest.raises(RecordingError, match="1000"):
        read_ridi(str(path), warn=False, max_uncompressed_bytes=1000)
