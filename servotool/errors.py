"""Error types; each carries the process exit code the CLI uses for it."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import ClassVar


class ServoError(Exception):
    """Base class: a failure the user should read as one line."""

    exit_code = 1


class UsageError(ServoError):
    """Bad input: unknown code, value out of range, bad file or option."""

    exit_code = 2


class ProfileError(UsageError):
    """A profile is missing or broken."""


class MissingRole(UsageError):
    """A feature needs an entry by meaning (a role) that the drive's profile does not map."""

    def __init__(self, feature: str, role: str, profile_id: str, message: str | None = None) -> None:
        self.feature, self.role, self.profile_id = feature, role, profile_id
        super().__init__(message or f"{feature} needs role '{role}', which profile {profile_id} does not map")


class UnknownName(UsageError):
    """A code, group, class or profile id that is not there; `suggestions` are the closest that are."""

    def __init__(
        self, kind: str, name: str, profile_id: str | None, suggestions: Sequence[str] = (), known: Sequence[str] = ()
    ) -> None:
        self.kind, self.name, self.profile_id = kind, name, profile_id
        self.suggestions, self.known = list(suggestions), list(known)
        where = f" for profile {profile_id}" if profile_id else ""
        hint = ""
        if suggestions:
            hint = (
                "; did you mean "
                + (
                    self.suggestions[0]
                    if len(self.suggestions) == 1
                    else ", ".join(self.suggestions[:-1]) + " or " + self.suggestions[-1]
                )
                + "?"
            )
        super().__init__(f"unknown {kind} '{name}'{where}{hint}")


class DeviceError(ServoError):
    """The link or the drive failed: timeout, CRC error, Modbus exception."""

    exit_code = 1
    fault = ""  # for a failed exchange: silent, garbled, stray or extra (what the last try met)


class ModbusException(DeviceError):
    """The drive answered with a Modbus exception response."""

    NAMES: ClassVar[dict[int, str]] = {
        1: "illegal function",
        2: "illegal data address",
        3: "illegal data value",
        4: "slave device failure",
        5: "acknowledge",
        6: "slave device busy",
    }

    def __init__(self, code: int, what: str) -> None:
        self.code = code
        name = self.NAMES.get(code, "unknown exception")
        super().__init__(f"{what}: drive answered Modbus exception {code:02d} ({name})")


class VerifyError(ServoError):
    """A value read back differs from what was written, or an expectation failed."""

    exit_code = 3


class StopUnconfirmed(ServoError):
    """A motion ended, but reading the drive back could not prove the motor at rest, the servo as found and the
    motion's settings as they were (`report`: servotool.motion.stop.StopReport). Exit 4, over every other code."""

    exit_code = 4

    def __init__(self, message: str, report: object) -> None:
        super().__init__(message)
        self.stop_report = report


class FileProblem(UsageError):
    """A file that cannot be used as it is: 'FILE: [line N: ]PROBLEM' (cannot read, not UTF-8, invalid YAML)."""

    def __init__(self, path: object, problem: str, line: int | None = None) -> None:
        self.path, self.problem, self.line = path, problem, line
        super().__init__(f"{path}: " + (f"line {line}: " if line is not None else "") + problem)


@dataclass(frozen=True)
class SetupGap:
    """One motion-setup requirement the drive does not meet (yet)."""

    code: str
    differences: tuple[tuple[str, str, str], ...]  # (setting, wanted, now) for each part that differs
    assignments: tuple[str, ...]  # the `param set` arguments that make it so: CODE=VALUE or CODE.FIELD=VALUE
    power_cycle: bool  # takes effect only after a power cycle


class SetupRequired(UsageError):
    """Host motion refused: drive settings differ from what the feature needs.

    `missing` differ now; `waiting` are written but not in effect until a power cycle (known on the simulator);
    `save` tells that power-cycle settings must be stored in EEPROM (`param set --save`) to survive the cycle.
    The message states the facts; the CLI adds the commands that fix them.
    """

    def __init__(
        self, feature: str, missing: Sequence[SetupGap], waiting: Sequence[SetupGap] = (), save: bool = False
    ) -> None:
        self.feature, self.missing, self.waiting, self.save = feature, tuple(missing), tuple(waiting), save
        super().__init__(f"{feature} needs drive setup first: {', '.join(self.settings())}")

    def settings(self) -> list[str]:
        """'SETTING = wanted (now x)' for each difference, and the settings waiting for a power cycle."""
        parts = [f"{s} = {want} (now {now})" for g in self.missing for s, want, now in g.differences]
        return parts + [
            f"{a.replace('=', ' = ')} (set, in effect after a power cycle)" for g in self.waiting for a in g.assignments
        ]


class IdentityMismatch(UsageError):
    """The drive answering contradicts its profile's identity checks; nothing was written.

    `answers` say what the drive answered; `better` is (profile id, model) of a shipped profile it matches, or None.
    """

    def __init__(
        self, profile: str, model: str, unit: int, answers: Sequence[str], better: tuple[str, str] | None
    ) -> None:
        self.profile, self.model, self.unit, self.answers, self.better = profile, model, unit, tuple(answers), better
        fit = (
            f"it answers like profile {better[0]} ({better[1]}): use --profile {better[0]}"
            if better
            else "no shipped profile fits it"
        )
        super().__init__(
            f"unit {unit} is not the drive profile {profile} ({model}) describes: "
            f"{'; '.join(answers)}; {fit}; nothing was written (--no-identity-check skips this check)"
        )


class ProfileNotFound(UsageError):
    """A drive found without --profile fits no candidate profile, or several; `candidates` are (profile id, what
    its checks met) for each."""

    def __init__(self, unit: int, port: str, fits: bool, candidates: Sequence[tuple[str, str]]) -> None:
        self.unit, self.port, self.fits, self.candidates = unit, port, fits, tuple(candidates)
        listed = "; ".join(f"{pid}: {why}" for pid, why in self.candidates)
        if fits:
            text = f"unit {unit} on {port} fits several profiles ({listed}): choose one with --profile"
        else:
            text = f"unit {unit} on {port} answers but fits no profile ({listed}): name its profile with --profile"
        super().__init__(text)
