"""The manuals' example frames, rebuilt through the tool's own request path (profile entry -> codec -> pymodbus RTU
framer) and compared byte for byte; replies decoded the same way."""

from __future__ import annotations

from dataclasses import replace

import pytest

from servotool.drive import Drive
from servotool.errors import DeviceError, VerifyError
from servotool.model.codec import format_value, raw_to_words, words_to_raw
from servotool.model.loader import load_profile
from servotool.model.profile import Limits
from servotool.ops import params
from tests.frames import parse_response_frame, read_request_frame, write_request_frame


def hexb(text: str) -> bytes:
    return bytes.fromhex(text.replace(" ", ""))


def write_frame(profile_id: str, code: str, value: str) -> bytes:
    from servotool.model.codec import parse_value

    p = load_profile(profile_id)
    e = p.entry(code)
    words = raw_to_words(e, parse_value(e, value))
    return write_request_frame(1, e.address, words, multiple=len(words) > 1)


def read_frame(profile_id: str, code: str, count: int | None = None) -> bytes:
    e = load_profile(profile_id).entry(code)
    return read_request_frame(1, e.address, count or e.words)


def test_sd25_write_and_read_po109():
    assert write_frame("sd25", "Po109", "5") == hexb("01 06 00 6D 00 05 D8 14")  # L2871-2874
    assert read_frame("sd25", "Po109") == hexb("01 03 00 6D 00 01 15 D7")  # L2887-2890
    unit, fc, regs = parse_response_frame(hexb("01 03 02 00 C8 B9 D2"))  # L2894-2897
    e = load_profile("sd25").entry("Po109")
    assert (unit, fc) == (1, 3)
    assert f"{format_value(e, words_to_raw(e, regs))} {e.unit}" == "200 ms"


def test_sd25_32_bit_monitor_example_7():
    p = load_profile("sd25")
    low_first = next(e for e in p.of_class("Un") if e.address == 900)
    assert words_to_raw(low_first, [31073, 65534]) == -99999  # L2833


def test_sdc_single_writes():
    assert write_frame("sdc", "PN95", "1") == hexb("01 06 00 5F 00 01 78 18")  # B9, L926
    assert write_frame("sdc", "PN4", "2") == hexb("01 06 00 04 00 02 49 CA")  # B10, L928


def test_sdc_multi_register_read_and_write_of_pn9_pn10():
    p = load_profile("sdc")
    pn9, pn10 = p.entry("PN9"), p.entry("PN10")
    assert pn10.address == pn9.address + 1
    assert read_request_frame(1, pn9.address, 2) == hexb("01 03 00 09 00 02 14 09")  # B1
    assert parse_response_frame(hexb("01 03 04 00 01 00 01 6A 33"))[2] == [1, 1]  # B2
    assert write_request_frame(1, pn9.address, [5, 4]) == hexb("01 10 00 09 00 02 04 00 05 00 04 22 07")  # B3
    assert parse_response_frame(hexb("01 10 00 09 00 02 91 CA"))[:2] == (1, 16)  # B4


def test_sdc_un_reads_and_decoding():
    assert read_frame("sdc", "UN-9") == hexb("01 03 01 35 00 01 95 F8")  # B5 (address 309)
    e = load_profile("sdc").entry("UN-9")
    assert format_value(e, words_to_raw(e, parse_response_frame(hexb("01 03 02 00 03 F8 45"))[2])) == "0.3"  # B6
    assert read_frame("sdc", "UN-2") == hexb("01 03 01 2E 00 02 A5 FE")  # B7


def test_sdc_position_reply_misprinted_byte_count():
    """B8 prints byte count 01 before four data bytes: the tool must refuse it; with 04 it decodes to 362897."""
    with pytest.raises(DeviceError):
        parse_response_frame(hexb("01 03 01 F5 B1 00 03 D9 D9"))
    regs = parse_response_frame(hexb("01 03 04 F5 B1 00 03 D9 D9"))[2]
    assert regs == [0xF5B1, 0x0003]
    e = load_profile("sdc").entry("UN-2")
    assert words_to_raw(e, regs) == 362897  # "当前位置为 0362897"


def test_a_corrupted_crc_is_refused():
    with pytest.raises(DeviceError, match="CRC"):
        parse_response_frame(hexb("01 03 02 00 C8 B9 D3"))


# ----- display-encoded values (SD25 two-/four-parameter modes, manual L2823-2831) ---------------------------------
# CRCs of the frames below are not printed in the manual; they were checked with an independent CRC-16 routine.


def test_sd25_example_5_two_parameter_d_1_10_is_written_as_266():
    assert write_frame("sd25", "Po001", "d 1 10") == hexb("01 06 00 01 01 0A 59 9D")  # 0x010A = 266
    e = load_profile("sd25").entry("Po001")
    assert words_to_raw(e, parse_response_frame(hexb("01 03 02 01 0A 39 D3"))[2]) == 266
    assert format_value(e, 266) == "d 1 10"


def test_sd25_example_6_four_parameter_b1234_is_written_as_0x1234():
    assert write_frame("sd25", "Po300", "b1234") == hexb("01 06 01 2C 12 34 44 88")
    assert format_value(load_profile("sd25").entry("Po300"), 0x1234) == "b1234"


def test_cli_writes_the_manual_forms_with_the_examples_frames(cli):
    r = cli("--profile", "sd25", "--port", "sim", "-v", "param", "set", "--save", "Po001=d 1 10", "Po300=b1234")
    assert r.code == 0, r.err
    assert ">> 01 06 00 01 01 0a 59 9d" in r.err and ">> 01 06 01 2c 12 34 44 88" in r.err
    assert "d 1 21 -> d 1 10" in r.out and "b1000 -> b1234" in r.out
    r = cli("--profile", "sd25", "--port", "sim", "param", "get", "Po001", "Po300", "--json")
    assert [(v["value"], v["text"], v["raw"]) for v in r.json()] == [(266, "d 1 10", 266), (0x1234, "b1234", 0x1234)]
    assert r.json()[0]["fields"] == {"Y": 1, "X": 10}


def test_cli_code_field_set_changes_only_that_field(cli):
    assert cli("--profile", "sd25", "--port", "sim", "param", "set", "Po175=b1211").code == 0
    r = cli("--profile", "sd25", "--port", "sim", "-v", "param", "set", "po175.c=3")
    assert r.code == 0, r.err
    assert ">> 01 06 00 af 13 11" in r.err  # D, B, A kept: 0x1211 -> 0x1311
    r = cli("--profile", "sd25", "--port", "sim", "param", "get", "Po175", "Po175.C", "Po175.d", "--json")
    assert [v["value"] for v in r.json()] == [0x1311, 3, 1] and r.json()[0]["text"] == "b1311"
    assert r.json()[1]["meaning"] == "rigid direct coupling"
    r = cli("--profile", "sd25", "--port", "sim", "param", "get", "Po001.Y")
    assert "Po001.Y" in r.out and "1 (CCW seen from the shaft)" in r.out


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (("set", "Po175.C=4"), "Po175: field C=4 is out of range 1..3"),
        (("set", "Po001.X=22"), "Po001: field X=22 is out of range 0..21"),
        (("set", "Po001=d 2 21"), "Po001: field Y=2 is out of range 0..1"),
        (("set", "Po175.Q=1"), "Po175: unknown field 'Q' (fields: D, C, B, A)"),
        (("set", "Po109.X=1"), "Po109 (Acceleration time) has no fields"),
        (("get", "Po109.X"), "Po109 (Acceleration time) has no fields"),
        (("set", "Po175.C=1 2"), "Po175.C: '1 2' is not a single field value"),
        (("set", "Po175.C=2", "Po175.C=3"), "Po175.C is given twice"),
        (("set", "--raw", "Po175.C=2"), "--raw takes whole register values"),
    ],
)
def test_cli_bad_field_input_is_one_line_and_writes_nothing(cli, args, message):
    r = cli("--profile", "sd25", "--port", "sim", "-v", "param", *args)
    errors = [line for line in r.err.splitlines() if line.startswith("servotool: error:")]
    assert r.code == 2 and len(errors) == 1 and message in errors[0], r.err
    assert "Traceback" not in r.err and ">> 01 06" not in r.err and ">> 01 10" not in r.err


# ----- SDC B3: two adjacent parameters in one FC16, through the real `param set` path -----------------------------


def test_sdc_param_set_pn9_pn10_sends_the_manuals_single_fc16_frame(cli):
    r = cli("--profile", "sdc", "--port", "sim", "-v", "param", "set", "PN9=5", "PN10=4")
    assert r.code == 0, r.err
    assert ">> 01 10 00 09 00 02 04 00 05 00 04 22 07" in r.err  # B3
    assert "<< 01 10 00 09 00 02 91 ca" in r.err  # B4, the echo
    assert ">> 01 06" not in r.err
    r = cli("--profile", "sdc", "--port", "sim", "param", "get", "PN9", "PN10", "--json")
    assert [v["value"] for v in r.json()] == [5, 4]


class RecordingLink:
    """A register store that records each write request as (address, values, multiple)."""

    def __init__(self) -> None:
        self.regs: dict[int, int] = {}
        self.writes: list[tuple[int, list[int], bool]] = []

    def read(self, unit: int, address: int, count: int, *, spare: tuple[int, int] = (0, 0)) -> list[int]:
        return [self.regs.get(a, 0) for a in range(address, address + count)]

    def write(self, unit: int, address: int, values: list[int], *, multiple: bool = True) -> None:
        self.writes.append((address, list(values), multiple))
        self.regs.update({address + i: v for i, v in enumerate(values)})

    def close(self) -> None:
        pass


@pytest.mark.parametrize(
    ("limits", "expected"),
    [
        (Limits(max_write=60, write_multiple=True), [(9, [5, 4], True), (12, [7], False)]),
        (Limits(max_write=1, write_multiple=True), [(9, [5], False), (10, [4], False), (12, [7], False)]),
        (Limits(max_write=60, write_multiple=False), [(9, [5], False), (10, [4], False), (12, [7], False)]),
    ],
)
def test_adjacent_writes_share_one_request_within_the_drives_limits(limits, expected):
    profile = replace(load_profile("sdc"), limits=limits)
    link = RecordingLink()
    d = Drive(link, profile, 1)
    pn9, pn10, pn12 = (profile.entry(c) for c in ("PN9", "PN10", "PN12"))  # PN11 is not adjacent-written
    results = params.apply_set(d, params.PreparedSet([(pn9, 1, 5), (pn10, 1, 4), (pn12, 200, 7)], []))
    assert link.writes == expected
    assert [(r.entry.code, r.new) for r in results] == [("PN9", 5), ("PN10", 4), ("PN12", 7)]


def test_a_coalesced_write_the_drive_does_not_keep_is_a_verify_error():
    profile = load_profile("sdc")
    link = RecordingLink()
    link.write = lambda unit, address, values, multiple=True: link.regs.update({address: values[0]})  # drops PN10
    d = Drive(link, profile, 1)
    plan = params.PreparedSet([(profile.entry("PN9"), 1, 5), (profile.entry("PN10"), 1, 4)], [])
    with pytest.raises(VerifyError, match="PN10: wrote 4 but the drive reads back 0"):
        params.apply_set(d, plan)
