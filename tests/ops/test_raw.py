"""`ops.raw`: registers decoded as 16- and 32-bit values in either word order, polled on a clock, and written
several at once (FC16) with the values judged by pymodbus' own client."""

from __future__ import annotations

import pytest

from servotool.clock import VirtualClock
from servotool.connection import ConnectOptions, resolve
from servotool.errors import UsageError
from servotool.ops import raw
from servotool.session import open_drives
from tests.ops.plain_client import read_registers


@pytest.mark.parametrize(
    ("kind", "order", "words", "expected"),
    [
        ("uint16", "big", [0xFFFE, 7], [0xFFFE, 7]),
        ("int16", "big", [0xFFFE, 7], [-2, 7]),
        ("uint32", "big", [0x0001, 0x0002], [0x00010002]),
        ("uint32", "little", [0x0001, 0x0002], [0x00020001]),
        ("int32", "big", [0xFFFF, 0xFFFE], [-2]),
        ("int32", "little", [0xFFFE, 0xFFFF], [-2]),
        ("float32", "big", [0x3FC0, 0x0000], [1.5]),
        ("float32", "little", [0x0000, 0xC120], [-10.0]),
    ],
)
def test_words_decode_by_type_and_word_order(kind, order, words, expected):
    values = raw.decode(0x2100, words, kind, order)
    assert [v.value for v in values] == expected
    step = raw.width(kind)
    assert [v.address for v in values] == [0x2100 + i * step for i in range(len(expected))]
    assert [list(v.words) for v in values] == [words[i : i + step] for i in range(0, len(words), step)]


def test_a_bad_type_or_word_order_is_a_usage_error():
    with pytest.raises(UsageError, match="--type"):
        raw.decode(0, [1], "float64")
    with pytest.raises(UsageError, match="--word-order"):
        raw.decode(0, [1, 2], "int32", "middle")


def test_poll_reads_count_times_on_its_clock(sim_dir):
    clock = VirtualClock()
    with open_drives(resolve(ConnectOptions(port="sim", profile="dsx7e")), notice=lambda _m: None) as (d,):
        raw.write_registers(d, 0x2100, [400, 401])
        rows = list(raw.poll(d, 0x2100, 1, "uint32", interval=0.5, polls=3, clock=clock))
        with pytest.raises(UsageError, match="--count"):
            raw.poll(d, 0x2100, 1, interval=0.5, polls=0)
        with pytest.raises(UsageError, match="--interval"):
            raw.poll(d, 0x2100, 1, interval=0)
    assert [t for t, _ in rows] == [0.0, 0.5, 1.0]
    assert [[v.value for v in values] for _, values in rows] == [[400 << 16 | 401]] * 3


def test_fc16_write_is_read_back_by_a_plain_client(serve, cli):
    port = serve("dsx7e")
    r = cli("--port", port, "-P", "dsx7e", "raw", "write", "0x2100=400,401,402", "--yes", "--json")
    assert r.code == 0, r.err
    assert r.json()["value"] == [400, 401, 402] and r.json()["verified"] is True
    assert read_registers(port, 0x2100, 3) == [400, 401, 402]
    refused = cli("--port", port, "-P", "dsx7e", "raw", "write", "0x2100=400,70000", "--yes")
    assert refused.code == 2 and "16 bits" in refused.err
    assert read_registers(port, 0x2100, 3) == [400, 401, 402]  # nothing of a refused list was written


def test_fc04_reaches_the_drive_through_the_one_master_and_is_refused(serve):
    from servotool.errors import ModbusException

    port = serve("sd25")
    with open_drives(resolve(ConnectOptions(port=port, profile="sd25")), notice=lambda _m: None) as (d,):
        assert raw.read_values(d, 101, 1) != []  # FC03 answers
        with pytest.raises(ModbusException) as refused:
            raw.read_values(d, 101, 1, fc=4)
        assert refused.value.code == 1
        assert raw.read_values(d, 101, 1)[0].value == raw.read_values(d, 101, 1)[0].value  # the line stays in step
