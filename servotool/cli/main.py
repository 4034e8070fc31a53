"""The `servotool` command: global options, sub-command groups, error handling."""

from __future__ import annotations

import atexit
import os
import signal
import sys
import threading
from typing import Any, NoReturn

import typer

from servotool import __version__
from servotool.cli import complete
from servotool.cli.argv import hoist_globals
from servotool.cli.common import State, take_options
from servotool.cli.lazy import lazy, lazy_group
from servotool.cli.render import Verbosity, emit_json, err, json_emitted, new_command
from servotool.connection import ConnectOptions
from servotool.errors import ServoError, StopUnconfirmed

# Each command's module is imported when that command runs (a typer app or a command function, "module:name"); the
# help is the one line `servotool --help` lists.
COMMANDS = {
    "param": lazy(
        "servotool.cli.param:app",
        "servotool.cli.backup:app",
        "servotool.cli.apply:app",
        help="Read, set, list, back up and restore drive parameters.",
    ),
    "profiles": lazy("servotool.cli.profiles:app", help="List, show and check drive profiles."),
    "sim": lazy("servotool.cli.sim:app", help="The simulated drive: serve it, configure its machine, reset it."),
    "alarm": lazy("servotool.cli.alarm:app", help="Show, clear and list the drive's alarms."),
    "tune": lazy(
        "servotool.cli.tune:app",
        "servotool.cli.tune_score:app",
        "servotool.cli.tune_functions:app",
        help="Inertia, gains, response scores and the drive's tuning functions.",
    ),
    "monitor": lazy("servotool.cli.monitor:monitor", help="Watch live values with units, min/max and a trend."),
    "jog": lazy("servotool.cli.jog:jog", help="JOG the motor, timed or by keys; first says what stops it."),
    "stop": lazy("servotool.cli.stop:stop", help="Stop the motor, whatever moved it; then read it back at rest."),
    "run": lazy("servotool.cli.run:run", help="Validate a commissioning plan, then run it on one or more axes."),
    "raw": lazy("servotool.cli.raw:app", help="Read and write registers by address (outside the profile)."),
    "scan": lazy("servotool.cli.scan:scan", help="Find drives on a bus and the profile each matches."),
    "doctor": lazy("servotool.cli.doctor:doctor", help="Link health: round trips, echo, errors, adapter latency."),
    "trace": lazy("servotool.cli.trace:trace", help="Capture entries around a trigger, as fast as the line allows."),
    "plot": lazy("servotool.cli.plot:plot", help="Draw any servotool CSV in the terminal or as a PNG."),
    "shell": lazy("servotool.cli.shell:shell", help="One open port, the same commands at a prompt, live status."),
    "fleet": lazy("servotool.cli.fleet:app", help="Many machines at once: backup, drift and apply per inventory."),
    "log": lazy("servotool.cli.log:log", help="The change log: every value servotool changed, per drive or machine."),
}

app = typer.Typer(
    name="servotool",
    no_args_is_help=True,
    add_completion=True,
    pretty_exceptions_enable=False,
    rich_markup_mode=None,  # plain help: rich's panels load markdown and pygments (cli/lazy.py)
    help="Commission and tune AC servo drives over Modbus RTU (real or simulated).",
    context_settings={"help_option_names": ["-h", "--help"]},
    cls=lazy_group(COMMANDS),
)


def _version(value: bool) -> None:
    if value:
        print(f"servotool {__version__}")
        raise typer.Exit()


@app.callback()
def main(
    ctx: typer.Context,
    port: str = typer.Option(
        None,
        "--port",
        "-p",
        help="Serial port (/dev/ttyUSB0, COM3), tcp://HOST:PORT (RTU over TCP) or 'sim'. Env: SERVOTOOL_PORT.",
    ),
    baud: int = typer.Option(None, "--baud", "-b", help="Baud rate (default: the profile's). Env: SERVOTOOL_BAUD."),
    parity: str = typer.Option(None, "--parity", help="N, E or O (default: the profile's). Env: SERVOTOOL_PARITY."),
    stopbits: int = typer.Option(None, "--stopbits", help="1 or 2 (default: the profile's). Env: SERVOTOOL_STOPBITS."),
    unit: int = typer.Option(
        None, "--unit", "-u", help="Modbus unit id 1..247 (default: the profile's). Env: SERVOTOOL_UNIT."
    ),
    timeout: float = typer.Option(
        None,
        "--timeout",
        help="Response timeout in seconds, beyond the request's and reply's time on the wire at the baud rate "
        "(a long reply at 2400 baud is waited for). Env: SERVOTOOL_TIMEOUT.",
    ),
    retries: int = typer.Option(None, "--retries", help="Retries after a timeout. Env: SERVOTOOL_RETRIES."),
    echo: str = typer.Option(
        None,
        "--echo",
        help="auto|on|off: the RS485 adapter echoes what it sends (default auto: "
        "found out on the first exchange). Env: SERVOTOOL_ECHO.",
    ),
    turnaround_ms: float = typer.Option(
        None,
        "--turnaround-ms",
        help="Quiet time after a reply before the next "
        "request, for slow drives (default 0). Env: SERVOTOOL_TURNAROUND_MS.",
    ),
    silence_ms: float = typer.Option(
        None,
        "--silence-ms",
        help="Silence that ends a frame (default: 3.5 characters at the baud rate). Env: SERVOTOOL_SILENCE_MS.",
    ),
    heartbeat: str = typer.Option(
        None,
        "--heartbeat",
        help="dtr|rts: a hardware dead-man. Toggle this control line of the USB-RS485 adapter at each keep-alive "
        "beat of a motion, for a retriggerable watchdog relay wired to the drive's enable input or main contactor "
        "(README: the hardware dead-man); it stops toggling when the motion ends, on a late beat and on every exit. "
        "RTS only where the adapter does not use RTS to switch its RS485 driver's direction. Serial ports only. "
        "Env: SERVOTOOL_HEARTBEAT.",
    ),
    heartbeat_timeout_ms: float = typer.Option(
        None,
        "--heartbeat-timeout-ms",
        help="The watchdog relay's time: it drops the drive this long after the last toggle (default 1000). "
        "Env: SERVOTOOL_HEARTBEAT_TIMEOUT_MS.",
    ),
    profile: str = typer.Option(
        None,
        "--profile",
        "-P",
        autocompletion=complete.profiles,
        help="Drive profile id or YAML file (default: found from the drive's answers; for sim: dsx7e). "
        "Env: SERVOTOOL_PROFILE.",
    ),
    no_identity_check: bool = typer.Option(
        None,
        "--no-identity-check",
        help="Skip the check, made before "
        "any write, that the drive answering is the one the profile describes. "
        "Env: SERVOTOOL_NO_IDENTITY_CHECK=1.",
        show_default=False,
    ),
    boost: bool = typer.Option(
        None,
        "--boost/--no-boost",
        help="Raise the line for identification, trace, backup and restore where the profile allows (SD25 to "
        "57600 baud; default: unless another device answers on the bus); --boost even then. Env: SERVOTOOL_BOOST.",
        show_default=False,
    ),
    verbose: int = typer.Option(0, "--verbose", "-v", count=True, help="Show every Modbus frame in hex."),
    quiet: bool = typer.Option(False, "--quiet", "-q", help="Only results and errors."),
    explain: bool = typer.Option(
        False,
        "--explain",
        help="Cautions in full (why an entry is not confirmed by the "
        "manual, what a missing watchdog means), not one line each.",
    ),
    version: bool = typer.Option(False, "--version", callback=_version, is_eager=True, help="Show the version."),
) -> None:
    """Commission and tune AC servo drives over Modbus RTU (real or simulated).

    Options also come from SERVOTOOL_* environment variables and the config file (~/.config/servotool/config.yaml
    on Linux; override with SERVOTOOL_CONFIG); the command line wins.
    """
    take_options(
        ctx,
        ConnectOptions(
            port=port,
            baud=baud,
            parity=parity,
            stopbits=stopbits,
            unit=unit,
            timeout=timeout,
            retries=retries,
            profile=profile,
            echo=echo,
            turnaround_ms=turnaround_ms,
            silence_ms=silence_ms,
            heartbeat=heartbeat,
            heartbeat_timeout_ms=heartbeat_timeout_ms,
            no_identity_check=no_identity_check or None,
            boost=boost,
        ),
    )
    Verbosity.level = -1 if quiet else verbose
    Verbosity.explain = explain


def run() -> None:
    """Console-script entry point: one clear line (and with --json a JSON object) and an exit code for every
    failure; Ctrl-C exits 130 after flushing what was produced."""
    _end(_run())


def _run() -> int:
    _interrupt_on_termination()
    if hasattr(sys.stdout, "reconfigure"):
        sys.stdout.reconfigure(line_buffering=True)  # streamed lines reach a pipe as they are made
    return dispatch(sys.argv[1:], State())  # the options given, filled in by main(); fix commands repeat them


def dispatch(argv: list[str], given: State) -> int:
    """Run one command line through the app (the process's, or one typed in `servotool shell`, whose `given`
    holds the port it keeps open): its exit status, every failure said in one line."""
    root = typer.main.get_command(app)
    args = list(argv)
    as_json = "--json" in args[: args.index("--")] if "--" in args else "--json" in args
    since = _stops_made()  # a shell runs many commands in one process: the stops of this one count
    new_command()
    try:
        args = hoist_globals(root, args)
        result = root.main(args=args, prog_name="servotool", standalone_mode=False, obj=given)
    except ServoError as exc:
        from servotool.cli.messages import error_code, error_text  # words for a failure, loaded on one

        text = error_text(exc, given.options, Verbosity.level > 0)
        return _fail(error_code(exc), text, exc.exit_code, as_json, exc, since)
    except (KeyboardInterrupt, typer.Abort) as exc:
        # click turns Ctrl-C into Abort: what the interrupt carries (notes, the stop's report) is on its cause
        return _fail("interrupted", "interrupted", 130, as_json, exc.__cause__ or exc, since)
    except BrokenPipeError:  # `| head` closed the pipe: nothing more to say, to anyone
        _broken_pipe()
    except Exception as exc:
        if (code := _usage_error(exc, as_json, since)) is not None:
            return code
        if os.environ.get("SERVOTOOL_DEBUG"):  # a bug: still one line for the user, the traceback on request
            raise
        return _fail(
            "internal",
            f"internal error: {type(exc).__name__}: {exc} (SERVOTOOL_DEBUG=1 shows the traceback)",
            1,
            as_json,
            exc,
            since,
        )
    if result == 130:  # typer turns Ctrl-C into a silent exit 130: say it as for any failure
        return _fail("interrupted", "interrupted", 130, as_json, None, since)
    status = result if isinstance(result, int) else 0
    report = _stop_report(None, since)
    if report is not None:  # a command that moved ends with what the drive was read to be
        err.print(f"servotool: {report.describe()}", markup=False)
        if not report.confirmed:
            return STOP_UNCONFIRMED
    return status


def _broken_pipe() -> NoReturn:
    sys.stderr.close()
    os._exit(141)


def _end(status: int) -> NoReturn:
    """Exit with status once the exit handlers have run and the output is flushed, without tearing the interpreter
    down module by module: that teardown, which no command needs (files are closed where they are written), took
    a one-shot command ~20 ms, an eighth of its run. Where a thread that is not a daemon still runs, the usual
    exit waits for it."""
    run_exit_handlers = getattr(atexit, "_run_exitfuncs", None)
    others = [t for t in threading.enumerate() if t is not threading.main_thread() and not t.daemon]
    if run_exit_handlers is None or others:
        sys.exit(status)
    try:
        _flush(sys.stdout)
        run_exit_handlers()
        _flush(sys.stdout)
        _flush(sys.stderr)
    except BrokenPipeError:
        _broken_pipe()
    os._exit(status)


def _flush(stream: object) -> None:
    if flush := getattr(stream, "flush", None):  # None under pythonw
        flush()


def _terminated(signum: int, _frame: object) -> None:
    raise KeyboardInterrupt


def _interrupt_on_termination() -> None:
    """A terminate or hang-up signal unwinds like Ctrl-C, so every `finally` puts back what it changed on a drive
    (the EEPROM switch); only kill -9 skips them, and the host's journal covers that."""
    for name in ("SIGTERM", "SIGHUP"):
        if hasattr(signal, name):
            signal.signal(getattr(signal, name), _terminated)


STOP_UNCONFIRMED = 4  # the exit status of a command whose motion's stop could not be proven (errors.StopUnconfirmed)


def _stops_made() -> int:
    """How many stops this process has made so far (motion/stop.py, looked at only where a motion ran)."""
    stops = sys.modules.get("servotool.motion.stop")
    return len(stops.reports()) if stops is not None else 0


def _stop_report(exc: BaseException | None, since: int = 0) -> Any:
    """The stop report the last line gives: the one a failure carries, else the first unproven or the last stop
    this command made (the process's stops from `since` on)."""
    attached = getattr(exc, "stop_report", None)
    if attached is not None:
        return attached
    stops = sys.modules.get("servotool.motion.stop")
    return stops.final(stops.reports()[since:]) if stops is not None else None


def _fail(code: str, message: str, status: int, as_json: bool, exc: BaseException | None = None, since: int = 0) -> int:
    """Say why on stderr (and as a JSON object on stdout for --json, unless the command printed its own); what the
    failure left (its notes) follows, and where a motion ran the last line says what its stop read back."""
    sys.stdout.flush()
    err.print(f"servotool: {'error: ' if code not in ('interrupted', 'internal') else ''}{message}", markup=False)
    for note in getattr(exc, "__notes__", ()):
        err.print(f"servotool: {note}", markup=False)
    report = _stop_report(exc, since)
    if report is not None:
        if not isinstance(exc, StopUnconfirmed):  # its own message is the line
            err.print(f"servotool: {report.describe()}", markup=False)
        if not report.confirmed:
            status, code = STOP_UNCONFIRMED, "stop_unconfirmed"
    if as_json and not json_emitted():
        error = {"code": code, "message": message, "exit_status": status}
        emit_json({"error": error, **({"stop": report.as_json()} if report is not None else {})})
    return status


def _usage_error(exc: Exception, as_json: bool, since: int = 0) -> int | None:
    """Report typer's own usage errors (bad option value, unknown option) in one line; None for other exceptions.

    Matched by shape: typer vendors click privately, so its exception classes are not importable API.
    """
    message, code = getattr(exc, "format_message", None), getattr(exc, "exit_code", None)
    if not callable(message) or not isinstance(code, int):
        return None
    ctx = getattr(exc, "ctx", None)
    if type(exc).__name__ == "NoArgsIsHelpError" and ctx is not None:
        if text := str(message()).strip():  # typer's rich help printed itself when the error was made
            print(text)
        return code
    where = f" (see '{ctx.command_path} --help')" if ctx is not None else ""
    return _fail("usage", f"{' '.join(str(message()).split())}{where}", code, as_json, None, since)


if __name__ == "__main__":  # `python -m servotool.cli.main` runs too, rather than exiting 0 having done nothing
    run()
