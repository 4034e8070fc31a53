"""`servotool raw read`: typed values as a table, CSV and JSON (numbers as numbers), and polling by count."""

from __future__ import annotations

import csv
import io
import json

SIM = ("--port", "sim")


def test_typed_read_as_json_csv_and_table(cli):
    assert cli(*SIM, "raw", "write", "0x2100=400,401").code == 0
    r = cli(*SIM, "raw", "read", "0x2100", "--type", "uint32", "--word-order", "little", "--json")
    assert r.code == 0, r.err
    assert r.json() == [
        {"address": 0x2100, "type": "uint32", "value": 401 << 16 | 400, "words": [400, 401], "entry": "Pn100"}
    ]
    r = cli(*SIM, "raw", "read", "0x2100", "2", "--type", "int16", "--csv")
    rows = list(csv.DictReader(io.StringIO(r.out)))
    assert [(int(x["address"]), int(x["value"]), x["entry"]) for x in rows] == [
        (0x2100, 400, "Pn100"),
        (0x2101, 401, "Pn101"),
    ]
    r = cli(*SIM, "raw", "read", "0x2100", "--type", "int32")
    assert r.code == 0 and str(400 << 16 | 401) in r.out and "0x0190 0x0191" in r.out


def test_polling_prints_one_row_per_poll_and_stops_after_count(cli):
    r = cli(*SIM, "raw", "read", "0x2100", "2", "--interval", "0.05", "--count", "3", "--json")
    assert r.code == 0, r.err
    rows = [json.loads(line) for line in r.out.splitlines()]
    assert len(rows) == 3 and all(isinstance(x["values"]["8448"], int) for x in rows)
    assert [x["t"] for x in rows] == sorted(x["t"] for x in rows)
    r = cli(*SIM, "raw", "read", "0x2100", "2", "--interval", "0.05", "--count", "2", "--csv")
    assert r.out.splitlines()[0] == "t,0x2100,0x2101" and len(r.out.splitlines()) == 3


def test_bad_read_options_fail_in_one_line(cli):
    for args, word in [
        (("--count", "2"), "--interval"),
        (("--type", "float64"), "--type"),
        (("--csv", "--json"), "not both"),
        (("--interval", "0", "--count", "1"), "--interval"),
    ]:
        r = cli(*SIM, "raw", "read", "0x2100", *args)
        assert r.code == 2 and word in r.err and len(r.err.strip().splitlines()) == 1, (args, r.err)


def test_a_function_the_drive_lacks_is_said_in_one_line(cli):
    for profile in ("dsx7e", "sd25"):
        r = cli(*SIM, "-P", profile, "raw", "read", "0x0065", "--fc", "4")
        assert r.code == 1 and "exception 01 (illegal function)" in r.err, r.err
        assert "input register" in r.err and len([x for x in r.err.splitlines() if "error" in x]) == 1
    r = cli(*SIM, "raw", "read", "0x2100", "--fc", "5")
    assert r.code == 2 and "--fc 5: reads are" in r.err


def test_coils_and_discrete_inputs_are_refused_by_every_profiled_drive(cli):
    for fc in ("1", "2"):
        r = cli(*SIM, "-P", "is620p", "raw", "read", "0", "8", "--fc", fc)
        assert r.code == 1 and "exception 01 (illegal function)" in r.err, r.err
    r = cli(*SIM, "raw", "read", "0", "--fc", "1", "--type", "int32")
    assert r.code == 2 and "bits" in r.err


def test_coil_writes_are_refused_by_the_drive_and_bad_ones_before_the_port(cli):
    for args in (("0x10=1", "--fc", "5"), ("0x10=1,0,1", "--fc", "15")):
        r = cli(*SIM, "raw", "write", *args)
        assert r.code == 1 and "coil(s)" in r.err and "exception 01 (illegal function)" in r.err, r.err
    for args, word in [
        (("0x10=1,0", "--fc", "5"), "--fc 15"),
        (("0x10=2", "--fc", "5"), "0 or 1"),
        (("0x2100=5", "--fc", "16"), "--fc 6"),
        (("0x2100=5", "--fc", "3"), "writes are"),
    ]:
        r = cli(*SIM, "raw", "write", *args)
        assert r.code == 2 and word in r.err and "SIMULATED" not in r.err, (args, r.err)
