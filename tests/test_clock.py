"""One clock: every library module reads and waits on time through servotool/clock.py, so a run on virtual time
(tests, benchmarks) is the same code as a run on a real line."""

from __future__ import annotations

import ast
from pathlib import Path

from servotool.clock import VirtualClock, utc_now
from servotool.drive import Drive
from servotool.model.loader import load_profile
from servotool.model.profile import LineSettings
from servotool.ops.monitor import Monitor, default_entries
from servotool.ops.scan import scan
from servotool.sim.firmware import build_drive
from servotool.sim.virtual import VirtualLink

PACKAGE = Path(__file__).resolve().parent.parent / "servotool"
TIME_READERS = {
    ("time", "monotonic"),
    ("time", "sleep"),
    ("time", "time"),
    ("time", "perf_counter"),
    ("time", "strftime"),
    ("time", "localtime"),
    ("datetime", "now"),
    ("datetime", "utcnow"),
    ("datetime", "today"),
    ("date", "today"),
}


def _reads_time(path: Path) -> list[str]:
    found = []
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if (
            isinstance(node, ast.Attribute)
            and isinstance(node.value, ast.Name)
            and (node.value.id, node.attr) in TIME_READERS
        ):
            found.append(f"{path.relative_to(PACKAGE.parent)}:{node.lineno}: {node.value.id}.{node.attr}")
        if isinstance(node, ast.ImportFrom) and node.module == "time":
            found.append(f"{path.relative_to(PACKAGE.parent)}:{node.lineno}: from time import ...")
    return found


def test_only_the_clock_module_reads_or_waits_on_time():
    found = [
        hit
        for path in sorted(PACKAGE.rglob("*.py"))
        if path.name != "clock.py" or path.parent != PACKAGE
        for hit in _reads_time(path)
    ]
    assert found == []


def _virtual(profile: str = "dsx7e") -> tuple[Drive, VirtualLink, VirtualClock]:
    clock = VirtualClock(1000.0)
    p = load_profile(profile)
    link = VirtualLink([build_drive(p, 1, clock, persist=False)], clock)
    return Drive(link, p, 1), link, clock


def test_monitor_samples_on_the_clock_it_is_given():
    d, _link, clock = _virtual()
    mon = Monitor(d, default_entries(d.profile), clock)
    samples = list(mon.run(10, 2.0))  # 2 s of virtual time: no real waiting
    assert len(samples) == 20 and samples[0].t == 0.0
    assert abs(samples[-1].t - 1.9) < 0.01 and abs(mon.achieved_rate - 10) < 0.1
    assert clock.now() >= 1001.9
    assert samples[0].wall == utc_now(VirtualClock(1000.0))


def test_scan_times_itself_on_the_clock_it_is_given():
    d, link, clock = _virtual()
    before = clock.now()
    result = scan("/dev/virtual", [1], [LineSettings()], [d.profile], open_link=lambda _s: link, clock=clock)
    assert [f.unit for f in result.found] == [1]
    assert result.seconds == clock.now() - before > 0


def test_doctor_times_the_link_on_the_clock_it_is_given():
    from servotool.link.ports import LinkSettings as PortSettings
    from servotool.ops.doctor import check
    from servotool.sim.server import EmbeddedSim

    profile = load_profile("dsx7e")
    sim = EmbeddedSim([build_drive(profile, 1, persist=False)])
    try:
        health = check(PortSettings(sim.port, timeout=1.0, retries=1), 1, profile, 5, clock=VirtualClock(7.0))
    finally:
        sim.close()
    assert len(health.rtts) == 5 and health.rtts == [0.0] * 5 and health.seconds == 0.0  # virtual time stood
