"""End-to-end CLI tests against the simulated drive, through the real RTU path."""

from __future__ import annotations

import json


def test_get_reads_defaults_and_says_simulated(cli):
    r = cli("--port", "sim", "param", "get", "Pn004", "Pn100", "--json")
    assert r.code == 0, r.err
    data = r.json()
    assert [d["code"] for d in data] == ["Pn004", "Pn100"]
    assert data[0]["value"] == 250 and data[1]["value"] == 32.0 and data[1]["unit"] == "1/s"
    assert r.err.count("SIMULATED") == 1


def test_set_converts_units_verifies_and_persists_between_invocations(cli):
    r = cli("--port", "sim", "param", "set", "Pn100=40.5", "Pn120=-12.5")
    assert r.code == 0, r.err
    assert "32.0 -> 40.5" in r.out
    r = cli("--port", "sim", "param", "get", "Pn100", "Pn120", "--json")
    assert [d["raw"] for d in r.json()] == [405, -125]


def test_set_unchanged_value_writes_nothing(cli):
    r = cli("--port", "sim", "-v", "param", "set", "Pn100=32")
    assert r.code == 0
    assert "already 32.0" in r.err
    assert ">> 01 06" not in r.err  # no write frame went out


def test_verbose_shows_real_rtu_frames_with_crc(cli):
    r = cli("--port", "sim", "-v", "param", "get", "Pn004")
    # FC03 at 0x2004, count 1: CRC computed by pymodbus' framer
    assert ">> 01 03 20 04 00 01" in r.err
    assert "<< 01 03 02 00 fa" in r.err


def test_power_cycle_parameter_takes_effect_only_after_power_cycle(cli, sim_dir):
    r = cli("--port", "sim", "param", "set", "Pn008=20000", "--json")
    assert r.code == 0
    assert r.json()["changed"][0]["effect"] == "power_cycle"
    state = json.loads(next(sim_dir.glob("dsx7e-unit1.json")).read_text())
    assert state["ram"]["Pn008"] == 20000 and state["effective"]["Pn008"] == 10000
    assert cli("--port", "sim", "param", "get", "Pn008", "--json").json()[0]["value"] == 20000
    r = cli("sim", "reset", "--power-cycle")
    assert r.code == 0 and "Pn008" in r.out
    state = json.loads(next(sim_dir.glob("dsx7e-unit1.json")).read_text())
    assert state["effective"]["Pn008"] == 20000


def test_list_changed_and_group(cli):
    cli("--port", "sim", "param", "set", "Pn101=25")
    r = cli("--port", "sim", "param", "list", "--changed", "--json")
    assert [d["code"] for d in r.json()] == ["Pn101"]
    r = cli("--port", "sim", "param", "list", "--group", "gain")
    assert r.code == 0 and "Pn101" in r.out and "Pn512" not in r.out and "*" in r.out


def test_bad_input_is_one_line_and_writes_nothing(cli, sim_dir):
    cases = [
        (("param", "set", "Pn100=99999"), 2, "out of range"),
        (("param", "set", "Pn100=fast"), 2, "is not a number"),
        (("param", "set", "Un000=5"), 2, "not a settable parameter"),
        (("param", "set", "Pn999=5"), 2, "unknown code 'Pn999'"),
        (("param", "set", "Pn100"), 2, "is not CODE=VALUE"),
        (("param", "get", "Pn999"), 2, "unknown code"),
        (("param", "list", "--group", "nosuch"), 2, "unknown group"),
        (("param", "list", "--class", "Xn"), 2, "unknown class 'Xn' (classes: Pn, Un, Sn)"),
        (("--unit", "abc", "param", "list"), 2, "Invalid value for '--unit'"),
        (("--unit", "0", "param", "list"), 2, "bad unit id 0"),
        (("--timeout", "nan", "param", "list"), 2, "bad timeout nan"),
        (("--baud", "0", "param", "list"), 2, "bad baud rate 0"),
        (("param", "nosuch"), 2, "No such command 'nosuch'"),
        (("sim", "reset", "--power-cycle", "--unit", "999"), 2, "bad unit id 999"),
        (("sim", "serve", "--port", "tcp://127.0.0.1:0", "--stopbits", "5"), 2, "bad stop bits 5"),
    ]
    for args, code, text in cases:
        r = cli("--port", "sim", *args)
        assert r.code == code, (args, r.err)
        assert text in r.err, (args, r.err)
        assert "Traceback" not in r.err
        assert len([ln for ln in r.err.splitlines() if ln.startswith("servotool: error")]) == 1
    assert not list(sim_dir.glob("*.json"))  # no simulated drive was even created
    # one bad value among good ones: nothing at all is written
    r = cli("--port", "sim", "param", "set", "Pn101=20", "Pn100=99999")
    assert r.code == 2
    assert cli("--port", "sim", "param", "get", "Pn101", "--json").json()[0]["value"] == 18.0


def test_unknown_profile_and_bad_port(cli):
    r = cli("--port", "sim", "--profile", "nosuch", "param", "list")
    assert r.code == 2 and "unknown profile 'nosuch'" in r.err
    r = cli("--port", "/dev/ttyNOPE0", "--profile", "dsx7e", "param", "get", "Pn004")
    assert r.code == 1 and "cannot open port /dev/ttyNOPE0" in r.err
    r = cli("--port", "tcp://nohost", "--profile", "dsx7e", "param", "get", "Pn004")
    assert r.code == 2 and "expected tcp://HOST:PORT" in r.err
    r = cli("param", "get", "Pn004")
    assert r.code == 2 and "no port given" in r.err


def test_options_from_environment_and_config_file(cli, tmp_path):
    r = cli("param", "get", "Pn004", "--json", env={"SERVOTOOL_PORT": "sim"})
    assert r.code == 0 and r.json()[0]["value"] == 250
    cfg = tmp_path / "cfg.yaml"
    cfg.write_text("port: sim\nprofile: dsx7e\n")
    r = cli("param", "get", "Pn004", "--json", env={"SERVOTOOL_CONFIG": str(cfg)})
    assert r.code == 0
    cfg.write_text("colour: red\n")
    r = cli("param", "get", "Pn004", env={"SERVOTOOL_CONFIG": str(cfg)})
    assert r.code == 2 and "unknown option(s) colour" in r.err
    for text, why in (
        ("timeout: true\n", "timeout must be a number"),
        ("port: [\n", "line 2: invalid YAML"),
        ("port: s\xefm\n", "not UTF-8"),
    ):
        cfg.write_bytes(text.encode("latin-1"))
        r = cli("param", "get", "Pn004", env={"SERVOTOOL_CONFIG": str(cfg)})
        assert r.code == 2 and why in r.err and len(r.err.splitlines()) == 1, r.err


def test_quiet_prints_only_results_and_errors(cli):
    r = cli("-q", "--port", "sim", "param", "get", "Pn004", "--json")
    assert r.code == 0 and r.err == "" and r.json()[0]["value"] == 250
    r = cli("--port", "sim", "param", "get", "Pn004")
    assert r.err.strip().startswith("servotool: SIMULATED drive")


def test_profiles_list_show_check(cli, tmp_path):
    r = cli("profiles", "list", "--json")
    assert r.code == 0 and "dsx7e" in [p["id"] for p in r.json()]
    r = cli("profiles", "show", "dsx7e", "--unverified")
    assert r.code == 0 and "Pn004" in r.out and "unverified" in r.out
    bad = tmp_path / "bad.yaml"
    bad.write_text("schema: 1\nid: bad\nentries: []\n")
    r = cli("profiles", "check", bad.as_posix(), "profiles/dsx7e.yaml")
    assert r.code == 2
    assert "missing required key 'model'" in r.out and "profiles/dsx7e.yaml: ok" in r.out
