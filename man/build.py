"""Write man/servotool.1 from the CLI itself, so every command and option is documented as it really is.

Run after changing the CLI: python man/build.py   (tests fail when the page is out of date)
"""

from __future__ import annotations

import sys
from datetime import date
from pathlib import Path

import typer

from servotool import __version__
from servotool.cli.examples import EXAMPLES
from servotool.cli.main import app

PAGE = Path(__file__).with_name("servotool.1")

HEAD = r""".TH SERVOTOOL 1 "{date}" "servotool {version}" "User Commands"
.SH NAME
servotool \- commission and tune AC servo drives over Modbus RTU
.SH SYNOPSIS
.B servotool
.RI [ global-options ]
.I command
.RI [ options ]
.RI [ arguments ]
.SH DESCRIPTION
.B servotool
reads, writes, backs up and restores drive parameters, watches live values, captures triggered traces and draws
them, jogs the motor, identifies the load inertia and sets gains (with a report of charts), and runs whole
commissioning plans, over Modbus RTU (RS485, CRC\-16), against a real
drive or a built\-in simulated one.
Each drive family is described by a YAML profile that keeps the vendor's own parameter codes
(for example SD25 \fBPo109\fR, IS620P \fBH09\-06\fR, SDC \fBPN22\fR, DSX7E \fBPn004\fR).
.PP
The port is a serial device (\fB/dev/ttyUSB0\fR, \fBCOM3\fR), \fBtcp://\fIHOST\fB:\fIPORT\fR (RTU framing over a
TCP serial gateway) or \fBsim\fR (a simulated drive answering in the same process, as \fBsim serve\fR answers on a
port; the client still speaks real RTU frames with CRC).
Output that comes from a simulated drive says so once on standard error.
.PP
Anything that moves the motor first prints what stops the motor if this program stops (kill, crash, pulled
cable) and the bound: "if this program stops, the motor stops within X rev (Y s)" (\fBdead_man\fR and
\fBsafety\fR in \fB\-\-json\fR; never hidden by \fB\-q\fR). With a travel limit, the planned travel and that bound
must fit inside it: an identification or step check lowers its speed until they do, a JOG is refused naming the
speed that fits.
However a motion ends (its end, Ctrl\-C, SIGTERM, SIGHUP, a lost line, an error, a failed check) one stop sequence
runs, which a second Ctrl\-C cannot interrupt: zero speed, rest, the servo back as found, the heartbeat stopped
and forced inputs released, every parameter the motion wrote (its protections too) put back, then the drive read
back. The last line says what it read ("stopped, servo off" and the
values read back; "nothing moved: at rest, servo off" for a Ctrl\-C before the first motion) or, where that could
not be proven, "COULD NOT CONFIRM THE MOTOR STOPPED" and why, with exit status 4.
.B servotool stop
stops a drive whatever moved it.
.TS
l l l.
Drive	If the host dies	Bound
DSX7E	watchdog Pn620 (fed by Fn032) stops it, E25; simulator only, not in the manual	speed x (Pn620 + ramp/2)
IS620P	the running multi\-segment position move (H11 segment 1) ends and stops	one segment and one braking
SD25	nothing: no Modbus timeout; forced DIs ignore wired inputs	none: \fB\-\-no\-dead\-man\fR or \fB\-\-heartbeat\fR
SDC	nothing: no Modbus timeout, no bounded route	none: \fB\-\-no\-dead\-man\fR or \fB\-\-heartbeat\fR
.TE
With \fB\-\-heartbeat dtr|rts\fR a control line of the USB\-RS485 adapter toggles at every beat of a motion for a
retriggerable watchdog relay on the drive's main contactor; the bound is then the relay's time
(\fB\-\-heartbeat\-timeout\-ms\fR). For a motion's duration servotool also sets the drive's own protections
where the profile maps them (speed limit, SD25's overtravel fence and locked\-rotor trip, SDC's saturation trip) and
puts them back; SD25's DIs are forced while it moves, so its wired inputs are ignored (main power still stops it).
The IS620P route is unverified (the start of a segment is the general IS620P manual's); see
\fBservotool profiles show \fIID\fB \-\-unverified\fR for each profile's route, its manual lines and the simulator's
extensions. The simulator stops nothing the manual does not: \fBsim config \-\-fake\-watchdog on\fR (NOT REAL, off
by default) is the only exception.
On drives whose Modbus motion route needs the drive set up for it (the profile's \fBmotion_setup\fR: SD25,
IS620P, SDC) those settings are read first; when any differs nothing moves and the error names each one with the
\fBservotool param set\fR command that fixes it (servotool never writes them itself).
.PP
Before a command's first request on a real port, servotool reads the profile's identity checks (firmware and
model entries and a few signature addresses, one or two requests): a drive that answers otherwise is refused
(exit 2) with what it answered and the shipped profile it matches, before anything is written; a check that
cannot tell warns once.
\fB\-\-no\-identity\-check\fR skips it.
\fBservotool scan\fR finds the drives on a bus and the profile each one matches.
"""

TAIL = r""".SH PLAN FILES
A plan for \fBservotool run\fR is YAML (loaded safely: values are data, nothing but these steps can run).
Optional top keys \fBport\fR, \fBprofile\fR, \fBbaud\fR, \fBparity\fR, \fBstopbits\fR, \fBtimeout\fR,
\fBretries\fR (the command line wins), \fBunits\fR (a list of unit ids: several axes on one line; each step
runs on every axis in turn, \fB\-\-unit\fR picks one of them), \fBallow_outside\fR and \fBoverwrite\fR (see
below); then \fBsteps\fR, a list run in order:
.TP
.B "set: {CODE: VALUE, ...}"
Write parameters in engineering units, verified by read\-back; unchanged values are not rewritten.
.TP
.B "expect: {CODE: VALUE | {value: V, tol: T} | {min: A, max: B}, ...}"
Read parameters or monitors and fail (exit 3) unless each is within the bounds (a bare VALUE allows half a
resolution step).
.TP
.BR "backup: FILE | {file: FILE, overwrite: BOOL}" ", " "restore: FILE"
Back up to or restore from FILE; \fB{unit}\fR in the name is replaced by the unit id, and with several units a
name without it gets \fB\-unit\fIN\fR before its suffix.
.TP
.B "jog: {speed: RPM, time: S, max_travel: REV, no_dead_man: BOOL}"
A timed JOG (negative speed: reverse) with the same checks and dead\-man as \fBservotool jog\fR;
\fBno_dead_man: true\fR acknowledges a drive without one (SD25, SDC), as \fB\-\-no\-dead\-man\fR does.
.TP
.B "tune inertia: {rigidity: N | bandwidth: HZ, travel: REV, max_speed: RPM, \
accel_time: MS, direction: D, repeats: N, gains: BOOL, check: BOOL, report: DIR, no_dead_man: BOOL}"
Identify the load inertia and write it, then the matching gains only with \fBrigidity\fR or \fBbandwidth\fR
(or \fBgains: true\fR: at the drive's current level); without them the gains are left as they are. Gains written
are step-checked: a failed check writes the previous ones back and fails the step, with the reason in the report;
\fBcheck: false\fR leaves the check out. \fBreport\fR
writes the same folder of charts as \fBtune inertia \-\-report\fR (beside the plan, one per axis).
.TP
.B "tune score: {repeats: N, travel: REV, speed: RPM, no_dead_man: BOOL}"
The measured score of \fBtune score\fR; the report carries every figure with its unit, spread and resolution.
.TP
.BR "tune friction:" ", " "tune notch:" ", " "tune gain-switching: {repeats: N, travel: REV, keep: BOOL, \
save: BOOL, method: drive|host, factor: X, no_dead_man: BOOL}"
What the command of the same name does (\fBmethod\fR for the notch, \fBfactor\fR for gain switching): score
before, set up, score after, keep only where the score improves beyond its spread (or \fBkeep: true\fR), put
back otherwise, read back; the report carries both scores and the comparison, and a later \fBsave:\fR stores
what was kept.
.TP
.BR "wait: S" ", " "alarm clear:" ", " "prompt: QUESTION"
Pause; reset the alarm; ask the operator (answered yes by \fB\-\-yes\fR; refused without a terminal).
.TP
.B save:
Make the plan's writes survive a power cycle the way the drive does it: its save function, or rewriting them
with its EEPROM switch set (nothing to do on drives that store every write).
.PP
Any step may carry \fBunit: N\fR or a list to run on some axes only.
A file a plan names is relative to the plan's folder (\fB~\fR is the home folder) and must stay inside that
folder, symbolic links followed, unless the plan says \fBallow_outside: true\fR; a file (or report folder) that
exists is replaced only where the step or the plan says \fBoverwrite: true\fR, or \fB\-\-force\fR does.
The whole plan is checked before the first step runs, the same way by \fB\-\-dry\-run\fR, which also lists
every file the run would write: each step against the profile, each file (outside the folder, existing without
overwrite, written twice, a restore whose file neither exists nor is written by an earlier step); every
problem is reported at once and names the plan's line.
Once the port is open, before anything is written, the run also reads the settings each motion step needs
(the profile's motion setup, with what earlier \fBset\fR steps write) and refuses a step the drive is not set up for.
A run writes a JSON report (steps, values written, results, timing) next to the plan as
\fIPLAN\fB.report.json\fR (replaced by each run) or to \fB\-\-report\fR (an existing file that is not a plan
report only with \fB\-\-force\fR), also when it fails or is interrupted.
.SH SHELL COMPLETION
\fBservotool \-\-install\-completion\fR installs completion for the current shell;
\fBservotool \-\-show\-completion\fR prints the script instead.
.SH ENVIRONMENT
.TP
.B "SERVOTOOL_PORT, SERVOTOOL_PROFILE, SERVOTOOL_UNIT, SERVOTOOL_BAUD, SERVOTOOL_PARITY, \
SERVOTOOL_STOPBITS, SERVOTOOL_TIMEOUT, SERVOTOOL_RETRIES, SERVOTOOL_TRAVEL"
Defaults for the global options of the same names; the command line wins.
.TP
.B SERVOTOOL_NO_IDENTITY_CHECK
\fB1\fR (or \fBtrue\fR) skips the identity check, like \fB\-\-no\-identity\-check\fR.
.TP
.B SERVOTOOL_CONFIG
Configuration file (default \fIconfig.yaml\fR in the user configuration folder: \fI~/.config/servotool\fR
on Linux, following \fB$XDG_CONFIG_HOME\fR) with the keys \fBport\fR, \fBprofile\fR,
\fBunit\fR, \fBbaud\fR, \fBparity\fR, \fBstopbits\fR, \fBtimeout\fR, \fBretries\fR,
\fBno_identity_check\fR, \fBtravel\fR (the default soft travel limit of \fBjog\fR, rev); used after
the environment.
.TP
.B SERVOTOOL_SIM_DIR
Where simulated drives keep their parameters and machine settings (default \fIsim\fR in the user state folder:
\fI~/.local/state/servotool/sim\fR on Linux, following \fB$XDG_STATE_HOME\fR).
.TP
.B SERVOTOOL_SIM_LINE_BAUD
\fBfast\fR, \fBfactory\fR or a baud rate: the line whose wire time delays each answer of a simulated drive whose
\fBsim config \-\-line\-baud\fR is left at \fBfactory\fR (the default: the connection's line, the profile's
factory settings unless given).
.TP
.B SERVOTOOL_BACKUP_DIR
Where automatic backups are written before a restore or a factory reset (default \fIbackups\fR in the user data
folder: \fI~/.local/share/servotool/backups\fR on Linux, following \fB$XDG_DATA_HOME\fR).
.TP
.B SERVOTOOL_DEBUG
Show the Python traceback of an internal error.
.SH EXIT STATUS
.TP
.B 0
Success.
.TP
.B 1
Device or I/O error: port, timeout, CRC, Modbus exception, a motion or identification that failed.
Also a difference found: \fBparam diff\fR, \fBparam apply \-\-check\fR, \fBfleet drift\fR and
\fBfleet apply \-\-check\fR when a drive differs.
.TP
.B 2
Usage or validation error: unknown code, value out of range, bad file or plan, missing confirmation, a drive
that does not answer like its profile.
Nothing is written to a drive before all values of a command are validated.
.TP
.B 3
Verification mismatch: a value read back differs, or an expectation or alarm clear failed.
.TP
.B 4
A motion's stop could not be proven: reading the drive back did not show the motor at rest, the servo as found and
the motion's settings as they were (or the drive did not answer); the last line says so in capitals. It wins over
every other status.
.TP
.B 5
Some drives of a \fBfleet\fR command failed; the others were done (the table and \fB\-\-json\fR say which).
.TP
.B 130
Interrupted (Ctrl\-C, SIGTERM, SIGHUP); any motion was stopped first, and the last line says what the drive read.
"""

SEE_ALSO = r""".SH SEE ALSO
.BR mbpoll (1),
.BR socat (1)
"""


def esc(text: str) -> str:
    """Escape text for roff: backslashes, hyphens, and a leading dot or quote."""
    text = " ".join(text.split()).replace("\\", "\\e").replace("-", "\\-")
    text = "".join(c if ord(c) < 128 else f"\\[u{ord(c):04X}]" for c in text)
    return "\\&" + text if text[:1] in (".", "'") else text


def placeholder(p) -> str:
    """What an option's value is called on the page: its metavar, FILE for paths, else the option's own name."""
    if p.metavar:
        return p.metavar
    if getattr(p.type, "name", None) == "path":  # click's Path type (typer's for a pathlib.Path annotation)
        return "FILE"
    longest = max(p.opts, key=len).lstrip("-")
    return longest.upper().replace("-", "_")


def option_lines(cmd) -> list[str]:
    lines = []
    for p in cmd.params:
        if getattr(p, "hidden", False) or p.name in ("help", "install_completion", "show_completion"):
            continue
        if p.param_type_name == "argument":
            lines += [".TP", f".I {p.name.upper()}" + (" ..." if p.nargs == -1 else "")]
        else:
            names = ", ".join(f"\\fB{esc(o)}\\fR" for o in [*p.opts, *p.secondary_opts])
            meta = "" if p.is_flag or p.count else f" \\fI{esc(placeholder(p))}\\fR"
            lines += [".TP", names + meta]
        lines.append(esc(p.help or ""))
    return lines


def command_sections(group, prefix: str) -> list[str]:
    out = []
    for name in sorted(group.list_commands(None)):  # lazily loaded commands too
        cmd = group.get_command(None, name)
        full = f"{prefix} {name}"
        if hasattr(cmd, "commands"):
            if any(p.name != "help" for p in cmd.params):
                out += [".SS " + esc(full), esc(cmd.help or ""), *option_lines(cmd)]
            out += command_sections(cmd, full)
            continue
        out += [".SS " + esc(full), esc((cmd.help or "").split("\n\n")[0]), *option_lines(cmd)]
    return out


def example_lines() -> list[str]:
    """The EXAMPLES section: every command's examples (cli/examples.py), in the order they run."""
    lines = [
        ".SH EXAMPLES",
        "In this order they run on a fresh simulated drive (a test runs each), as on a real one; the SD25, IS620P and "
        "SDC motion examples need the drive set up for Modbus motion first (an error names the \\fBparam set\\fR "
        "that does it).",
    ]
    for _, line, what in EXAMPLES:
        lines += [".TP", f"\\fB{esc(line)}\\fR", esc(what)]
    return lines


def render() -> str:
    root = typer.main.get_command(app)
    body = [".SH GLOBAL OPTIONS", *option_lines(root), ".SH COMMANDS", *command_sections(root, "servotool")]
    head = HEAD.replace("{date}", date.today().strftime("%Y-%m")).replace("{version}", __version__)
    return head + "\n".join(body) + "\n" + TAIL + "\n".join(example_lines()) + "\n" + SEE_ALSO


if __name__ == "__main__":
    PAGE.write_text(render())
    sys.stdout.write(f"wrote {PAGE}\n")
