"""The `servotool` command: global options, sub-command groups, error handling."""

from __future__ import annotations

import os
import signal
import sys

import typer

from servotool import __version__
from servotool.cli import alarm, backup, jog, monitor, param, profiles, run, sim, tune
from servotool.cli.common import State, state
from servotool.cli.messages import error_text
from servotool.cli.render import Verbosity, err
from servotool.config import ConnectOptions
from servotool.errors import ServoError

app = typer.Typer(
    name="servotool", no_args_is_help=True, add_completion=True, pretty_exceptions_enable=False,
    help="Commission and tune AC servo drives over Modbus RTU (real or simulated).",
    context_settings={"help_option_names": ["-h", "--help"]},
)
# `param` is two groups of commands under one name: values (get, set, list) and files (backup, diff, restore, reset).
param_group = typer.Typer(no_args_is_help=True, help="Read, set, list, back up and restore drive parameters.")
param_group.add_typer(param.app)
param_group.add_typer(backup.app)
app.add_typer(param_group, name="param")
app.add_typer(profiles.app, name="profiles")
app.add_typer(sim.app, name="sim")
app.add_typer(alarm.app, name="alarm")
app.add_typer(tune.app, name="tune")
app.command("monitor")(monitor.monitor)
app.command("jog")(jog.jog)
app.command("run")(run.run)


def _version(value: bool) -> None:
    if value:
        print(f"servotool {__version__}")
        raise typer.Exit()


@app.callback()
def main(
    ctx: typer.Context,
    port: str = typer.Option(None, "--port", "-p", help="Serial port (/dev/ttyUSB0, COM3), tcp://HOST:PORT "
                             "(RTU over TCP) or 'sim'. Env: SERVOTOOL_PORT."),
    baud: int = typer.Option(None, "--baud", "-b", help="Baud rate (default: the profile's). Env: SERVOTOOL_BAUD."),
    parity: str = typer.Option(None, "--parity", help="N, E or O (default: the profile's). Env: SERVOTOOL_PARITY."),
    stopbits: int = typer.Option(None, "--stopbits", help="1 or 2 (default: the profile's). Env: SERVOTOOL_STOPBITS."),
    unit: int = typer.Option(None, "--unit", "-u", help="Modbus unit id 1..247 (default: the profile's). "
                             "Env: SERVOTOOL_UNIT."),
    timeout: float = typer.Option(None, "--timeout", help="Response timeout in seconds. Env: SERVOTOOL_TIMEOUT."),
    retries: int = typer.Option(None, "--retries", help="Retries after a timeout. Env: SERVOTOOL_RETRIES."),
    profile: str = typer.Option(None, "--profile", "-P", help="Drive profile id or YAML file (default for sim: "
                                "dsx7e). Env: SERVOTOOL_PROFILE."),
    verbose: int = typer.Option(0, "--verbose", "-v", count=True, help="Show every Modbus frame in hex."),
    quiet: bool = typer.Option(False, "--quiet", "-q", help="Only results and errors."),
    version: bool = typer.Option(False, "--version", callback=_version, is_eager=True, help="Show the version."),
) -> None:
    """Commission and tune AC servo drives over Modbus RTU (real or simulated).

    Options also come from SERVOTOOL_* environment variables and the config file (~/.config/servotool/config.yaml
    on Linux; override with SERVOTOOL_CONFIG); the command line wins.
    """
    state(ctx).options = ConnectOptions(port=port, baud=baud, parity=parity, stopbits=stopbits, unit=unit,
                                        timeout=timeout, retries=retries, profile=profile)
    Verbosity.level = -1 if quiet else verbose


def run() -> None:
    """Console-script entry point: one clear line and an exit code for every failure."""
    given = State()       # the options given on the command line, filled in by main(); fix commands repeat them
    _interrupt_on_termination()
    try:
        result = app(prog_name="servotool", standalone_mode=False, obj=given)
    except ServoError as exc:
        err.print(f"servotool: error: {error_text(exc, given.options)}", markup=False)
        sys.exit(exc.exit_code)
    except (KeyboardInterrupt, typer.Abort):
        err.print("servotool: interrupted", markup=False)
        sys.exit(130)
    except Exception as exc:
        if (code := _usage_error(exc)) is not None:
            sys.exit(code)
        if os.environ.get("SERVOTOOL_DEBUG"):  # a bug: still one line for the user, the traceback on request
            raise
        err.print(f"servotool: internal error: {type(exc).__name__}: {exc} (SERVOTOOL_DEBUG=1 shows the traceback)",
                  markup=False)
        sys.exit(1)
    sys.exit(result if isinstance(result, int) else 0)


def _terminated(signum: int, _frame: object) -> None:
    raise KeyboardInterrupt


def _interrupt_on_termination() -> None:
    """A terminate or hang-up signal unwinds like Ctrl-C, so every `finally` puts back what it changed on a drive
    (the EEPROM switch); only kill -9 skips them, and the host's journal covers that."""
    for name in ("SIGTERM", "SIGHUP"):
        if hasattr(signal, name):
            signal.signal(getattr(signal, name), _terminated)


def _usage_error(exc: Exception) -> int | None:
    """Report typer's own usage errors (bad option value, unknown option) in one line; None for other exceptions.

    Matched by shape: typer vendors click privately, so its exception classes are not importable API.
    """
    message, code = getattr(exc, "format_message", None), getattr(exc, "exit_code", None)
    if not callable(message) or not isinstance(code, int):
        return None
    ctx = getattr(exc, "ctx", None)
    if type(exc).__name__ == "NoArgsIsHelpError" and ctx is not None:
        print(ctx.get_help())
        return code
    where = f" (see '{ctx.command_path} --help')" if ctx is not None else ""
    err.print(f"servotool: error: {' '.join(str(message()).split())}{where}", markup=False)
    return code
