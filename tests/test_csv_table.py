"""The shared C CSV reader (fmus/native/common/csv_table.c) as the FMUs' loaders use it:
CRLF, a BOM, blank lines and long lines read as the plain file; hex floats are refused as
the Python twins' float() refuses them; the profile format's empty file is a header error
in both of its readers (TrackIrregularity and Trolley), as in its Python twin."""

from __future__ import annotations

import numpy as np
import pytest
from fmpy import simulate_fmu

from railfmu.fmus.cosim.slave import FMUError, Slave
from railfmu.models.track.irregularity import ProfileTable

PROFILE = "s,alignment,vertical_left,vertical_right\n0,0,0,0\n10,1e-3,2e-3,-1e-3\n20,0,0,0\n40,-2e-3,1e-3,0\n"
TABLE = "time,x,flag,n\n0.0,1.0,0,1\n0.5,2.0,1,2\n1.0,3.0,1,3\n"


def _track(fmu_dir, path):
    return simulate_fmu(str(fmu_dir / "TrackIrregularity.fmu"), stop_time=1.5, output_interval=0.01,
                        start_values={"psd_level": 0, "profile_file": str(path)})


def test_profile_crlf_blank_and_long_lines_read_as_the_plain_file(fmu_dir, tmp_path):
    plain, odd = tmp_path / "plain.csv", tmp_path / "odd.csv"
    plain.write_text(PROFILE)
    rows = PROFILE.splitlines()
    rows[2] += " " * 5000  # beyond the old 4096-character line buffers
    odd.write_bytes(("\r\n".join(rows[:3]) + "\r\n\r\n  \r\n" + "\r\n".join(rows[3:]) + "\r\n").encode())
    a, b = _track(fmu_dir, plain), _track(fmu_dir, odd)
    assert np.ptp(a["alignment_1"]) > 1e-3
    assert a.tobytes() == b.tobytes()
    assert ProfileTable.from_csv(odd).s.tolist() == ProfileTable.from_csv(plain).s.tolist()


@pytest.mark.parametrize("text, message", [
    ("", ":1: header must be s,alignment,vertical_left,vertical_right or position_m,vertical_left_m,vertical_right_m"),
    (PROFILE.replace("10,1e-3", "10,0x1p-10"), ":3: not a number: '0x1p-10'"),
])
def test_bad_profile_same_words_in_both_readers_and_python(fmu_dir, tmp_path, text, message):
    p = tmp_path / "bad.csv"
    p.write_text(text)
    with pytest.raises(ValueError, match="not a number|header must be") as py:
        ProfileTable.from_csv(p)
    assert str(py.value) == f"profile_file {p}{message}"
    with Slave(fmu_dir / "TrackIrregularity.fmu", "track") as s:
        with pytest.raises(FMUError):
            s.initialize(0.0, 1.0, {"psd_level": 0, "profile_file": str(p)})
        assert [m for st, _, m in s.messages if st == "Error"][0] == str(py.value)
    with Slave(fmu_dir / "Trolley.fmu", "trolley") as s:
        with pytest.raises(FMUError):
            s.initialize(0.0, parameters={"irregularity_file": str(p)})
        errors = [m for st, _, m in s.messages if st == "Error"]
    assert errors[0] == str(py.value).replace("profile_file", "irregularity_file", 1)


def _table_errors(fmu_dir, path):
    with Slave(fmu_dir / "SignalTable.fmu", "table") as s:
        try:
            s.initialize(0.0, 1.0, {"file": str(path), "column_1": "x", "boolean_column_1": "flag",
                                    "integer_column_1": "n"})
        except FMUError:
            pass
        return [m for st, _, m in s.messages if st == "Error"]


def test_signal_table_bom_crlf_and_hex(fmu_dir, tmp_path):
    p = tmp_path / "t.csv"
    p.write_bytes(b"\xef\xbb\xbf" + TABLE.replace("\n", "\r\n").encode())
    assert _table_errors(fmu_dir, p) == []
    p.write_text(TABLE.replace("2.0,1,2", "0x2p0,1,2"))
    assert _table_errors(fmu_dir, p) == [f"file {p}, line 3, column 2 (x): '0x2p0' is not a number"]
