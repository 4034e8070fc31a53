"""The manuals' example frames, rebuilt through the tool's own request path (profile entry -> codec -> pymodbus RTU
framer) and compared byte for byte; replies decoded the same way."""

from __future__ import annotations

import pytest

from servotool.codec import format_value, raw_to_words, words_to_raw
from servotool.errors import DeviceError
from servotool.profile import load_profile
from servotool.transport import parse_response_frame, read_request_frame, write_request_frame


def hexb(text: str) -> bytes:
    return bytes.fromhex(text.replace(" ", ""))


def write_frame(profile_id: str, code: str, value: str) -> bytes:
    from servotool.codec import parse_value

    p = load_profile(profile_id)
    e = p.entry(code)
    words = raw_to_words(e, parse_value(e, value))
    return write_request_frame(1, e.address, words, multiple=len(words) > 1)


def read_frame(profile_id: str, code: str, count: int | None = None) -> bytes:
    e = load_profile(profile_id).entry(code)
    return read_request_frame(1, e.address, count or e.words)


def test_sd25_write_and_read_po109():
    assert write_frame("sd25", "Po109", "5") == hexb("01 06 00 6D 00 05 D8 14")        # L2871-2874
    assert read_frame("sd25", "Po109") == hexb("01 03 00 6D 00 01 15 D7")              # L2887-2890
    unit, fc, regs = parse_response_frame(hexb("01 03 02 00 C8 B9 D2"))                # L2894-2897
    e = load_profile("sd25").entry("Po109")
    assert (unit, fc) == (1, 3)
    assert f"{format_value(e, words_to_raw(e, regs))} {e.unit}" == "200 ms"


def test_sd25_32_bit_monitor_example_7():
    p = load_profile("sd25")
    low_first = next(e for e in p.of_class("Un") if e.address == 900)
    assert words_to_raw(low_first, [31073, 65534]) == -99999                            # L2833


def test_sdc_single_writes():
    assert write_frame("sdc", "PN95", "1") == hexb("01 06 00 5F 00 01 78 18")           # B9, L926
    assert write_frame("sdc", "PN4", "2") == hexb("01 06 00 04 00 02 49 CA")            # B10, L928


def test_sdc_multi_register_read_and_write_of_pn9_pn10():
    p = load_profile("sdc")
    pn9, pn10 = p.entry("PN9"), p.entry("PN10")
    assert pn10.address == pn9.address + 1
    assert read_request_frame(1, pn9.address, 2) == hexb("01 03 00 09 00 02 14 09")     # B1
    assert parse_response_frame(hexb("01 03 04 00 01 00 01 6A 33"))[2] == [1, 1]         # B2
    assert write_request_frame(1, pn9.address, [5, 4]) == hexb("01 10 00 09 00 02 04 00 05 00 04 22 07")  # B3
    assert parse_response_frame(hexb("01 10 00 09 00 02 91 CA"))[:2] == (1, 16)          # B4


def test_sdc_un_reads_and_decoding():
    assert read_frame("sdc", "UN-9") == hexb("01 03 01 35 00 01 95 F8")                 # B5 (address 309)
    e = load_profile("sdc").entry("UN-9")
    assert format_value(e, words_to_raw(e, parse_response_frame(hexb("01 03 02 00 03 F8 45"))[2])) == "0.3"  # B6
    assert read_frame("sdc", "UN-2") == hexb("01 03 01 2E 00 02 A5 FE")                 # B7


def test_sdc_position_reply_misprinted_byte_count():
    """B8 prints byte count 01 before four data bytes: the tool must refuse it; with 04 it decodes to 362897."""
    with pytest.raises(DeviceError):
        parse_response_frame(hexb("01 03 01 F5 B1 00 03 D9 D9"))
    regs = parse_response_frame(hexb("01 03 04 F5 B1 00 03 D9 D9"))[2]
    assert regs == [0xF5B1, 0x0003]
    e = load_profile("sdc").entry("UN-2")
    assert words_to_raw(e, regs) == 362897                                              # "当前位置为 0362897"


def test_a_corrupted_crc_is_refused():
    with pytest.raises(DeviceError, match="CRC"):
        parse_response_frame(hexb("01 03 02 00 C8 B9 D3"))
