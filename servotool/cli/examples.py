"""Examples of every sub-command, in the order a first session would run them: each command's help shows its own,
the man page's EXAMPLES section shows them all (man/build.py), and a test runs each one against the simulator.

One entry: (sub-command, command line as typed in a POSIX shell, what it does). The SD25, SDC and IS620P motion
examples assume the drive set up for Modbus motion as the README shows (`param set` of the profile's motion_setup);
an example that ends otherwise than with exit 0 says so at the end of what it does ("(exit 130).").
"""

from __future__ import annotations

EXAMPLES: tuple[tuple[str, str, str], ...] = (
    ("profiles list", "servotool profiles list", "The built-in drive profiles."),
    ("profiles show", "servotool profiles show sd25 --unverified", "What the SD25 manual leaves open, and why."),
    ("profiles check", "servotool profiles check", "Validate every built-in profile (exit 2 on a problem)."),
    ("param find", "servotool -P sd25 param find jog speed", "Search a profile's entries; no drive needed."),
    ("param get", "servotool --port sim param get Pn004 Un000", "The inertia ratio and the motor speed."),
    ("param get", "servotool --port /dev/ttyUSB0 -P sd25 param get Po109", "A real drive on a USB-RS485 adapter."),
    ("param list", "servotool --port sim param list --group gain", "The gains, with defaults and changed marks."),
    ("param set", "servotool --port sim param set Pn100=40.0 Pn101=25.0", "Write, then verify by read-back."),
    ("param list", "servotool --port sim param list --changed", "Only what differs from the factory default."),
    ("param backup", "servotool --port sim param backup -o axis1.yaml", "Every parameter to a checksummed file."),
    ("param diff", "servotool --port sim param diff axis1.yaml", "The drive against a backup."),
    (
        "param diff",
        "servotool --port sim param diff --factory",
        "The drive against its factory defaults; they differ (exit 1).",
    ),
    ("param restore", "servotool --port sim param restore axis1.yaml --dry-run", "What a restore would write."),
    ("param restore", "servotool --port sim param restore axis1.yaml --yes", "Write the differences, verified."),
    ("raw read", "servotool --port sim raw read 0x2100 --type int32 --json", "A 32-bit value, high word first (FC03)."),
    ("raw write", "servotool --port sim raw write 0x2100=400", "One register (FC06), read back."),
    ("raw write", "servotool --port sim raw write 0x2100=400,401", "Two registers (FC16), read back."),
    ("raw read", "servotool --port sim raw read 0x2100 2 --interval 0.5 --count 3 --csv", "Three polls as CSV."),
    ("monitor", "servotool --port sim monitor Un000 Un002 --once", "One sample of speed and torque."),
    ("monitor", "servotool --port sim monitor --rate 20 --duration 2 --csv log.csv", "Two seconds, logged to CSV."),
    ("jog", "servotool --port sim jog --speed 300 --time 2", "JOG forward at 300 rpm for 2 s."),
    ("param set", "servotool --port sim -P sdc param set PN4=3", "SDC in JOG mode, as its jog needs."),
    ("jog", "servotool --port sim -P sdc jog -s 100 -t 1 --no-dead-man", "SDC has no dead-man: acknowledge it."),
    ("stop", "servotool --port sim stop", "Zero speed and servo off, read back (exit 4 if unproven)."),
    ("stop", "servotool --port sim -P sd25 stop --json", "SD25: its forced inputs released too (So-58)."),
    ("trace", "servotool --port sim trace Un000 Un002 --duration 0.5 -o start.csv", "Half a second, at once."),
    (
        "trace",
        "servotool --port sim trace Un000 --trigger 'Un000<100' -o stop.csv & "
        "servotool --port sim jog --speed 300 --time 3 && wait $!",
        "Catch the stop at the end of a JOG that a second command makes.",
    ),
    ("plot", "servotool plot start.csv", "Draw a CSV in the terminal."),
    ("plot", "servotool plot start.csv -o start.png", "The same as a PNG (needs matplotlib: the plot extra)."),
    ("alarm show", "servotool --port sim alarm show", "The current alarm, if any."),
    ("alarm history", "servotool --port sim alarm history", "The drive's alarm history, latest first."),
    ("alarm clear", "servotool --port sim alarm clear", "Reset the alarm (exit 3 if it stays active)."),
    ("sim config", "servotool sim config --load-ratio 5", "A simulated load of 5 times the rotor's inertia."),
    ("sim show", "servotool sim show", "The simulated drive's machine and running state."),
    ("tune gains", "servotool --port sim tune gains --yes --to 14", "Raise the rigidity level, step-checked."),
    (
        "tune inertia",
        "servotool --port sim tune inertia --yes --rigidity 16 --report tune-report",
        "Identify, write the ratio and gains; charts in the folder tune-report.",
    ),
    ("tune score", "servotool --port sim tune score --yes --save before.json", "Score the response: 3 runs."),
    (
        "tune score",
        "servotool --port sim tune score --yes --before before.json",
        "Score again and compare: a verdict only beyond the spread.",
    ),
    ("tune compare", "servotool tune compare before.json before.json", "Two saved scores, figure by figure."),
    ("tune resonance", "servotool --port sim tune resonance --yes", "Peaks after a step; the line's limit."),
    (
        "tune friction",
        "servotool --port sim tune friction --yes",
        "Friction compensation, kept only where the score improves.",
    ),
    (
        "tune notch",
        "servotool --port sim -P is620p tune notch --yes",
        "A notch at a resolved resonance, judged likewise (IS620P).",
    ),
    (
        "tune gain-switching",
        "servotool --port sim -P sd25 tune gain-switching --yes --no-dead-man",
        "Gain 2 while moving (SD25 Po130 = 2), kept only where it helps.",
    ),
    ("param reset", "servotool --port sim param reset --yes", "Factory defaults, after an automatic backup."),
    (
        "param apply",
        "servotool --port sim param apply examples/golden-gains.yaml --check --diff",
        "What the file would change, before/after; nothing written (exit 1).",
    ),
    (
        "param apply",
        "servotool --port sim param apply examples/golden-gains.yaml",
        "Write only what differs, read back: changed or unchanged.",
    ),
    ("sim reset", "servotool sim reset -P sd25 --power-cycle", "Power-cycle the simulated SD25."),
    ("run", "servotool run examples/commission.yaml --dry-run", "Check a plan against the profile; touch nothing."),
    (
        "run",
        "servotool run examples/tune-functions.yaml --dry-run",
        "A plan's score and friction steps, listed; nothing moves.",
    ),
    (
        "fleet backup",
        "servotool fleet backup examples/fleet.yaml -o snapshots",
        "Snapshot every machine's drives at once, a worker per bus.",
    ),
    (
        "fleet apply",
        "servotool fleet apply examples/fleet.yaml --check",
        "What each drive's golden file would change (exit 1).",
    ),
    (
        "fleet apply",
        "servotool fleet apply examples/fleet.yaml",
        "Every drive to its golden file; a failed one stops no other.",
    ),
    (
        "fleet drift",
        "servotool fleet drift examples/fleet.yaml",
        "Every drive against its golden file; exit 1 when one differs.",
    ),
    ("log", "servotool log --machine press-02", "What servotool changed on press-02: when, who, old -> new."),
    (
        "shell",
        "printf 'param get Pn004\\nalarm show\\n' | servotool --port sim shell",
        "One port opened once; piped lines run in turn.",
    ),
    (
        "sim serve",
        "servotool sim serve --port tcp://127.0.0.1:5020 --unit 1 --unit 2",
        "Two simulated drives for any Modbus RTU master, until Ctrl-C (exit 130).",
    ),
    ("scan", "servotool scan --port /dev/ttyUSB0 --units 1-10 --baud 9600 --format 8N1", "Find drives on a bus."),
    ("doctor", "servotool -P sd25 doctor --port /dev/ttyUSB0 --count 50", "Round trips, errors, adapter latency."),
)


def for_command(path: str) -> list[tuple[str, str]]:
    """The examples of one sub-command ('param get'): (command line, what it does)."""
    return [(line, what) for name, line, what in EXAMPLES if name == path]


def epilog(path: str) -> str | None:
    """The examples as the end of a command's help, kept line by line (click's \\b marker)."""
    found = for_command(path)
    if not found:
        return None
    lines = ["\b", "Examples:"]
    for line, what in found:
        lines += [f"  {part}" for part in line.replace(" & ", " &\n").split("\n")]  # a command on each line
        lines.append(f"      {what}")
    return "\n".join(lines)
