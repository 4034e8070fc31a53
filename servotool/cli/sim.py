"""`servotool sim ...`: serve the simulated drive to other masters, reset it."""

from __future__ import annotations

import typer

from servotool.cli.common import state
from servotool.cli.render import Verbosity, emit_json, info, out, table, trace_frame
from servotool.connection import SIM_DEFAULT_PROFILE, ConnectOptions, check_unit, line_format, merge
from servotool.errors import UsageError
from servotool.model.loader import load_profile
from servotool.model.profile import Profile
from servotool.model.quantity import quantity
from servotool.model.roles import sim_extensions
from servotool.sim import state as sim_state
from servotool.sim.device import SIM_SETTINGS, line_choice
from servotool.sim.line import LINE_ENV, Line, env_choice

app = typer.Typer(no_args_is_help=True, help="The simulated drive: serve it, configure its machine, reset it.")


def _profile(ctx: typer.Context, profile: str | None) -> Profile:
    return load_profile(profile or state(ctx).options.profile or SIM_DEFAULT_PROFILE)


def _target(ctx: typer.Context, profile: str | None, unit: int | None) -> tuple[Profile, int]:
    """The simulated drive the options name (falling back to the global options and the profile's unit)."""
    opts = merge(ConnectOptions(profile=profile, unit=unit), state(ctx).options)
    p = _profile(ctx, opts.profile)
    return p, check_unit(opts.unit if opts.unit is not None else p.default_unit)


@app.command("serve")
def serve(
    ctx: typer.Context,
    port: str = typer.Option(
        ...,
        "--port",
        "-p",
        help="Serial device (/dev/ttyS1, a socat pty) or "
        "tcp://127.0.0.1:N (RTU framing over TCP; N=0 picks a free port).",
    ),
    profile: str = typer.Option(None, "--profile", "-P", help="Profile to simulate (default: dsx7e)."),
    units: list[int] = typer.Option(
        None, "--unit", "-u", help="Unit id to answer; repeat for several drives on one line (default: the profile's)."
    ),
    baud: int = typer.Option(None, "--baud", "-b", help="Serial baud rate (default: the profile's)."),
    parity: str = typer.Option(None, "--parity", help="N, E or O (default: the profile's)."),
    stopbits: int = typer.Option(None, "--stopbits", help="1 or 2 (default: the profile's)."),
    line_baud: str = typer.Option(
        None,
        "--line-baud",
        help="factory|fast|BAUD: delay each answer by its wire time on this line (default: as 'sim config "
        "--line-baud' says, then SERVOTOOL_SIM_LINE_BAUD, then factory; on a serial port its own timing).",
    ),
    faults: str = typer.Option(
        None,
        "--faults",
        help="A bad line (tcp:// ports): KIND:RATE[,...], RATE as 0.05 or 5% per reply: crc, drop, late (by "
        "--late-ms), stale (held until just before the reply 1-8 requests later), duplicate (again after a gap of "
        "0..--fault-gap-ms), unit (from another unit id), truncate, garbage, burst (2-6 faulty replies in a row), "
        "echo (per request: it comes back after such a gap), or mixed (all of them).",
    ),
    fault_seed: int = typer.Option(1, "--fault-seed", help="Seed of the line's faults (same seed, same faults)."),
    late_ms: float = typer.Option(500.0, "--late-ms", help="How late a 'late' reply comes, ms."),
    gap_ms: float = typer.Option(50.0, "--fault-gap-ms", help="Longest gap before a duplicate or an echo, ms."),
    ignore_writes: str = typer.Option(
        None,
        "--ignore-writes",
        help="CODE|ADDRESS[,...] (tcp:// ports): a write to these registers is acknowledged but not made, as by "
        "a drive that ignores it (FC06 or FC16 covering one; reads then show the old value).",
    ),
    response_delay: float = typer.Option(0.0, "--response-delay", help="Delay every reply by this many ms."),
    echo: bool = typer.Option(False, "--echo", help="Echo each request back to the master, as some adapters do."),
) -> None:
    """Serve simulated drives in the foreground (Ctrl-C stops) for any Modbus RTU master."""
    from servotool.sim.faults import LineFaults, parse_addresses, parse_rates
    from servotool.sim.server import serve_units

    p = _profile(ctx, profile)
    ids = [check_unit(u) for u in units or [p.default_unit]]
    if len(set(ids)) != len(ids):
        raise UsageError("each --unit may be given once")
    choice = _line_choice(line_baud)
    line = line_format(ConnectOptions(baud=baud, parity=parity, stopbits=stopbits), p)

    def ready(where: str, served: Line, took: dict[int, list[str]]) -> None:
        info(
            f"servotool: SIMULATED {p.model} drive(s) unit {','.join(map(str, ids))} serving on {where} "
            f"({line.baud} {line.bytesize}{line.parity}{line.stopbits}); {served.describe()}; Ctrl-C stops"
        )
        for u, codes in took.items():
            if codes:
                info(f"servotool: unit {u} powered on; now in effect: {', '.join(codes)}")

    bad_line = None
    if faults or response_delay or echo or ignore_writes:
        bad_line = LineFaults(
            parse_rates(faults or ""),
            seed=fault_seed,
            late_s=late_ms / 1000.0,
            gap_s=gap_ms / 1000.0,
            response_delay_s=response_delay / 1000.0,
            echo=echo,
            ignore_writes=parse_addresses(p, ignore_writes or ""),
        )
    try:
        serve_units(
            port,
            p,
            ids,
            line,
            line_baud=choice,
            trace=trace_frame if Verbosity.level > 0 else None,
            ready=ready,
            faults=bad_line,
        )
    except KeyboardInterrupt:  # its only way to stop, and still exit 130 as every command at Ctrl-C
        info("servotool: simulator stopped")
        raise typer.Exit(130) from None


@app.command("reset")
def reset(
    ctx: typer.Context,
    profile: str = typer.Option(None, "--profile", "-P", help="Profile of the simulated drive."),
    unit: int = typer.Option(None, "--unit", "-u", help="Unit id (default: the profile's)."),
    power_cycle: bool = typer.Option(
        False,
        "--power-cycle",
        help="Power-cycle: parameters stored in EEPROM reload and pending power-cycle changes take effect.",
    ),
    factory: bool = typer.Option(False, "--factory", help="Erase the simulated drive's state: factory defaults."),
    as_json: bool = typer.Option(False, "--json", help="Machine-readable output."),
) -> None:
    """Power-cycle or wipe a simulated drive (its state file)."""
    p, u = _target(ctx, profile, unit)
    if power_cycle == factory:
        raise UsageError("give exactly one of --power-cycle or --factory")
    if factory:
        path = sim_state.factory_reset(p, u)
        if as_json:
            emit_json({"profile": p.id, "unit": u, "reset": "factory", "state_file": str(path)})
            return
        out.print(f"simulated {p.model} unit {u}: factory state ({path} removed)", markup=False)
        return
    pending = sim_state.power_cycle(p, u)
    if as_json:
        emit_json({"profile": p.id, "unit": u, "reset": "power_cycle", "took_effect": pending})
        return
    out.print(
        f"simulated {p.model} unit {u}: power-cycled" + (f"; now in effect: {', '.join(pending)}" if pending else ""),
        markup=False,
    )


@app.command("config")
def config(
    ctx: typer.Context,
    profile: str = typer.Option(None, "--profile", "-P", help="Profile of the simulated drive."),
    unit: int = typer.Option(None, "--unit", "-u", help="Unit id (default: the profile's)."),
    load_ratio: float = typer.Option(None, "--load-ratio", help=SIM_SETTINGS["load_ratio"][4]),
    friction: float = typer.Option(None, "--friction", help=SIM_SETTINGS["friction"][4]),
    viscous: float = typer.Option(None, "--viscous", help=SIM_SETTINGS["viscous"][4]),
    load_torque: float = typer.Option(None, "--load-torque", help=SIM_SETTINGS["load_torque"][4]),
    noise: float = typer.Option(None, "--noise", help=SIM_SETTINGS["noise"][4]),
    seed: int = typer.Option(None, "--seed", help=SIM_SETTINGS["seed"][4]),
    line_baud: str = typer.Option(None, "--line-baud", help=f"factory|fast|BAUD: {SIM_SETTINGS['line_baud'][4]}."),
    resonance_hz: float = typer.Option(None, "--resonance-hz", help=SIM_SETTINGS["resonance_hz"][4]),
    resonance_damping: float = typer.Option(None, "--resonance-damping", help=SIM_SETTINGS["resonance_damping"][4]),
    backlash_rad: float = typer.Option(None, "--backlash-rad", help=SIM_SETTINGS["backlash_rad"][4]),
    arm_gravity: float = typer.Option(None, "--arm-gravity", help=SIM_SETTINGS["arm_gravity"][4]),
    arm_angle: float = typer.Option(None, "--arm-angle", help=SIM_SETTINGS["arm_angle"][4]),
    gear: float = typer.Option(None, "--gear", help=SIM_SETTINGS["gear"][4]),
    cogging: float = typer.Option(None, "--cogging", help=SIM_SETTINGS["cogging"][4]),
    cogging_periods: int = typer.Option(None, "--cogging-periods", help=SIM_SETTINGS["cogging_periods"][4]),
    brake: str = typer.Option(
        None,
        "--brake",
        help="on|off: holding brake, closed while the servo is off "
        "(default on; off lets a gravity load fall, held back only by friction).",
    ),
    fake_watchdog: str = typer.Option(
        None,
        "--fake-watchdog",
        help="on|off, NOT REAL (default off): stop host "
        "motion after 500 ms of host silence on a drive whose manual documents no "
        "communication timeout. The real drive keeps running.",
    ),
    segment_restart: str = typer.Option(
        None,
        "--segment-restart",
        help="on|off (default off), segment route (IS620P): on, a start edge during a running segment restarts it "
        "at once from where the axis is; off, it waits until the segment has settled, and a falling edge brakes "
        "the segment (the stricter reading; the manual documents neither).",
    ),
    inputs: int = typer.Option(None, "--inputs", help=SIM_SETTINGS["inputs"][4] + ".", min=0, max=255),
    di_monitor: str = typer.Option(
        None,
        "--di-monitor",
        help="forced|terminals, NOT IN THE MANUAL as terminals (default forced): what the input monitor shows while "
        "the inputs are forced; the manual's words read as the forced levels.",
    ),
    missing: str = typer.Option(
        None,
        "--missing",
        help="CODE,...: entries this drive lacks (answered with "
        "exception 02, like a firmware without them); '' restores them all.",
    ),
    as_json: bool = typer.Option(False, "--json", help="Machine-readable output."),
) -> None:
    """Set the simulated machine's true properties (persisted with the drive; never readable over Modbus)."""
    brake_on = None if brake is None else _on_off(brake, "--brake")
    fake_on = None if fake_watchdog is None else _on_off(fake_watchdog, "--fake-watchdog")
    restart_on = None if segment_restart is None else _on_off(segment_restart, "--segment-restart")
    monitor = None if di_monitor is None else _choice(di_monitor, "--di-monitor", DI_MONITOR)
    p, u = _target(ctx, profile, unit)
    if missing is not None:
        sim_state.set_missing(p, u, [c.strip() for c in missing.split(",") if c.strip()])
    status = sim_state.configure(
        p,
        u,
        load_ratio=load_ratio,
        friction=friction,
        viscous=viscous,
        load_torque=load_torque,
        noise=noise,
        seed=seed,
        line_baud=_line_choice(line_baud),
        brake=brake_on,
        fake_watchdog=fake_on,
        segment_restart=restart_on,
        inputs=inputs,
        di_monitor=monitor,
        resonance_hz=resonance_hz,
        resonance_damping=resonance_damping,
        backlash_rad=backlash_rad,
        arm_gravity=arm_gravity,
        arm_angle=arm_angle,
        gear=gear,
        cogging=cogging,
        cogging_periods=cogging_periods,
    )
    if as_json:
        emit_json({"profile": p.id, "unit": u, "settings": status.settings, "missing": list(status.missing)})
        return
    _print_settings(status)


@app.command("show")
def show(
    ctx: typer.Context,
    profile: str = typer.Option(None, "--profile", "-P", help="Profile of the simulated drive."),
    unit: int = typer.Option(None, "--unit", "-u", help="Unit id (default: the profile's)."),
    as_json: bool = typer.Option(False, "--json", help="Machine-readable output."),
) -> None:
    """The simulated machine's settings and the drive's state file."""
    status = sim_state.status(*_target(ctx, profile, unit))
    run = status.running
    if as_json:
        emit_json(
            {
                "profile": status.profile.id,
                "unit": status.unit,
                "state_file": str(status.state_file),
                "settings": status.settings,
                "pending_power_cycle": status.pending_power_cycle,
                "eeprom_writes": status.eeprom_writes,
                "running": {
                    "servo_on": run.servo_on,
                    "alarm": run.alarm,
                    "position": quantity(run.position_rev, "rev"),
                }
                if run
                else None,
                "missing": list(status.missing),
                "extensions": [{"what": x.what, "why": x.why} for x in sim_extensions(status.profile)],
            }
        )
        return
    _print_settings(status)
    _print_extensions(status.profile)
    if run is not None:
        out.print(
            f"running state as last saved (a powered drive keeps it until a power cycle): servo "
            f"{'on' if run.servo_on else 'off'}, alarm {run.alarm or 'none'}, "
            f"position {run.position_rev:.3f} rev",
            markup=False,
        )


def _line_choice(value: str | None) -> str | int | None:
    if value is None:
        return None
    try:
        return line_choice(value)
    except ValueError as exc:
        raise UsageError(f"--line-baud: {exc}") from None


DI_MONITOR = ("forced", "terminals")


def _on_off(value: str, option: str) -> int:
    return _choice(value, option, ("off", "on"))


def _choice(value: str, option: str, names: tuple[str, ...]) -> int:
    """The index of a named choice (off/on, forced/terminals); UsageError naming the choices."""
    if value.lower() not in names:
        raise UsageError(
            f"{option} must be {' or '.join(names[::-1] if names == ('off', 'on') else names)}, not {value!r}"
        )
    return names.index(value.lower())


def _print_settings(status: sim_state.SimStatus) -> None:
    t = table(
        "Setting",
        "Value",
        "Meaning",
        title=f"simulated {status.profile.model} unit {status.unit} ({status.state_file})",
    )
    for name, value in status.settings.items():
        if name == "line_baud":
            over = env_choice() if value == "factory" else None
            shown = str(value) if over is None else f"{over} ({LINE_ENV})"
        else:
            shown = (
                ("on" if value else "off") if name in ("brake", "fake_watchdog", "segment_restart") else f"{value:g}"
            )
        shown = DI_MONITOR[int(value)] if name == "di_monitor" else shown
        t.add_row(name, shown, SIM_SETTINGS[name][4])
    out.print(t)
    if status.missing:
        out.print(f"entries this drive lacks (exception 02): {', '.join(status.missing)}", markup=False)
    if status.pending_power_cycle:
        out.print(f"waiting for a power cycle: {', '.join(status.pending_power_cycle)}", markup=False)


def _print_extensions(profile: Profile) -> None:
    """What this simulated drive does that the manual does not document (also in profiles show --unverified)."""
    found = sim_extensions(profile)
    if not found:
        out.print("simulator extensions: none (the simulated drive does what its profile documents)", markup=False)
        return
    out.print("simulator extensions (not on the real drive, or not in its manual):", markup=False)
    for x in found:
        out.print(f"  {x.what}: {x.why}", markup=False)
