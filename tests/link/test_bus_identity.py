"""One name for a bus, whatever its spelling (issue 30 item 6): the host's journal and write lock are keyed by it."""

from __future__ import annotations

import os

import pytest

from servotool.link.ports import bus_identity


@pytest.mark.parametrize("spelling", ["tcp://127.0.0.1:5020", "tcp://localhost:5020", "tcp://[::1]:5020"])
def test_every_loopback_spelling_of_a_tcp_port_is_one_bus(spelling):
    assert bus_identity(spelling) == "tcp://localhost:5020"


def test_a_tcp_host_is_known_by_its_address_and_an_unknown_one_by_its_name():
    assert bus_identity("tcp://10.1.2.3:502") == "tcp://10.1.2.3:502"
    assert bus_identity("tcp://10.1.2.3:503") != bus_identity("tcp://10.1.2.3:502")
    assert bus_identity("tcp://No-Such-Host.invalid:502") == "tcp://no-such-host.invalid:502"


@pytest.mark.parametrize("spelling", ["COM3", "com3", r"\\.\COM3", r"\\?\com3"])
def test_a_com_port_is_one_bus_in_any_case_and_prefix(spelling):
    assert bus_identity(spelling) == "COM3"


def test_a_serial_device_is_known_by_its_by_id_link_else_by_its_real_path(tmp_path):
    device = tmp_path / "ttyUSB1"
    device.touch()
    alias = tmp_path / "rs485"
    alias.symlink_to(device)
    by_id = tmp_path / "by-id"
    by_id.mkdir()
    assert bus_identity(str(alias), by_id) == os.path.realpath(device)  # no by-id link: the real path
    (by_id / "usb-FTDI_FT232R_A12345-if00-port0").symlink_to(device)
    for name in (str(device), str(alias)):
        assert bus_identity(name, by_id) == str(by_id / "usb-FTDI_FT232R_A12345-if00-port0")


def test_a_macos_dial_in_device_is_its_callout_twin():
    assert bus_identity("/dev/tty.usbserial-A1") == "/dev/cu.usbserial-A1" == bus_identity("/dev/cu.usbserial-A1")
