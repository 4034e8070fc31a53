"""Which drive answers: a profile's identity checks read from a unit, and the shipped profile that fits it best.

The check runs before any write (session.open_drives): a drive that contradicts its profile is refused, so a
parameter is never written at an address that means something else on the drive really there.
"""

from __future__ import annotations

from dataclasses import dataclass

from servotool.drive import Drive
from servotool.errors import DeviceError, IdentityMismatch, ModbusException, ProfileNotFound
from servotool.link.ports import Link
from servotool.model.codec import words_to_raw
from servotool.model.identity import read_plan
from servotool.model.loader import builtin_ids, load_profile
from servotool.model.profile import IdentityCheck, Profile

FITS, CONTRADICTS, UNKNOWN = "fits", "contradicts", "unknown"
MATCH, MISMATCH, INCONCLUSIVE = "match", "mismatch", "inconclusive"


@dataclass(frozen=True)
class Answer:
    """What one identity check read: a value, a Modbus exception, or nothing; and whether it fits the profile."""

    check: IdentityCheck
    raw: int | None = None
    exception: int | None = None
    verdict: str = UNKNOWN

    def describe(self, model: str) -> str:
        c = self.check
        where = f"{c.code} (address {c.address})" if c.code else c.label
        if self.raw is None:
            got = f"exception {self.exception:02d}" if self.exception is not None else "no answer"
            if self.exception == 2 and not c.absent:
                return f"{where} is not on this drive ({got})"
            return f"{where}: {got}"
        if c.absent:
            return f"{where} answers {self.raw} ({model} has no register there)"
        if c.range is not None and self.verdict == CONTRADICTS:
            return f"{where} reads {self.raw} ({model}: {c.range[0]}..{c.range[1]})"
        return f"{where} reads {self.raw}"

    def as_json(self) -> dict[str, object]:
        return {
            "code": self.check.code or None,
            "address": self.check.address,
            "raw": self.raw,
            "exception": self.exception,
            "verdict": self.verdict,
        }


@dataclass(frozen=True)
class Verdict:
    """One profile's identity checks against one unit."""

    profile: Profile
    unit: int
    answers: tuple[Answer, ...]

    @property
    def outcome(self) -> str:
        verdicts = [a.verdict for a in self.answers]
        if CONTRADICTS in verdicts:
            return MISMATCH
        return MATCH if verdicts and all(v == FITS for v in verdicts) else INCONCLUSIVE

    @property
    def score(self) -> int:
        """How strongly the answers fit: a value inside a range counts more than mere presence."""
        return sum(2 if a.check.range is not None else 1 for a in self.answers if a.verdict == FITS)

    def value(self, code: str) -> int | None:
        return next((a.raw for a in self.answers if code and a.check.code == code), None)

    @property
    def firmware(self) -> int | None:
        return self.value(self.profile.identity.firmware) if self.profile.identity else None

    @property
    def model(self) -> int | None:
        return self.value(self.profile.identity.model) if self.profile.identity else None

    def reasons(self, verdict: str) -> list[str]:
        """What the answers with this verdict say; the entries one request found missing, in one phrase."""
        picked = [a for a in self.answers if a.verdict == verdict]
        missing = [a for a in picked if a.exception == 2 and not a.check.absent]
        out = [a.describe(self.profile.model) for a in picked if a not in missing]
        if len(missing) > 1:
            first, last = missing[0].check, missing[-1].check
            out.insert(
                0,
                f"{', '.join(a.check.label for a in missing)} (addresses {first.address}-"
                f"{last.address + last.words - 1}) are not on this drive (exception 02)",
            )
        elif missing:
            out.insert(0, missing[0].describe(self.profile.model))
        return out

    def as_json(self) -> dict[str, object]:
        ident = self.profile.identity
        return {
            "profile": self.profile.id,
            "model": self.profile.model,
            "unit": self.unit,
            "outcome": self.outcome,
            "firmware": {"code": ident.firmware, "raw": self.firmware} if ident and ident.firmware else None,
            "drive_model": {"code": ident.model, "raw": self.model} if ident and ident.model else None,
            "answers": [a.as_json() for a in self.answers],
        }


def probe(link: Link, unit: int, profile: Profile, *, silent_ok: bool = False) -> Verdict:
    """Read a profile's identity checks from a unit (one or two requests) and judge each answer.

    A link failure (no answer) raises DeviceError, or with silent_ok counts as 'unknown'."""
    if profile.identity is None:
        return Verdict(profile, unit, ())
    answers: list[Answer] = []
    for start, count, checks in read_plan(profile.identity.checks, profile.limits.max_read):
        try:
            words = link.read(unit, start, count)
        except ModbusException as exc:
            answers += [_refused(c, exc.code) for c in checks]
            continue
        except DeviceError as exc:
            if not silent_ok:
                exc.args = (
                    f"checking the drive's identity: {exc.args[0] if exc.args else exc} "
                    f"(--no-identity-check skips the check)",
                )
                raise
            answers += [Answer(c) for c in checks]
            continue
        for c in checks:
            off = c.address - start
            answers.append(_judge(profile, c, words[off : off + c.words]))
    return Verdict(profile, unit, tuple(answers))


def _refused(check: IdentityCheck, code: int) -> Answer:
    """An exception 02 tells the address is not there; any other exception tells nothing about identity."""
    if code != 2:
        return Answer(check, exception=code)
    return Answer(check, exception=code, verdict=FITS if check.absent else CONTRADICTS)


def _judge(profile: Profile, check: IdentityCheck, words: list[int]) -> Answer:
    if check.absent:
        return Answer(check, words[0], verdict=CONTRADICTS)
    raw = words_to_raw(profile.entry(check.code), words)
    fits = check.range is None or check.range[0] <= raw <= check.range[1]
    return Answer(check, raw, verdict=FITS if fits else CONTRADICTS)


def shipped_profiles() -> list[Profile]:
    return [load_profile(pid) for pid in builtin_ids()]


def identify(link: Link, unit: int, profiles: list[Profile]) -> list[Verdict]:
    """Every profile's checks against one unit, best fit first (matches, by strength; then inconclusive ones)."""
    verdicts = [probe(link, unit, p, silent_ok=True) for p in profiles]
    rank = {MATCH: 0, INCONCLUSIVE: 1, MISMATCH: 2}
    return sorted(verdicts, key=lambda v: (rank[v.outcome], -v.score))


def best_fit(link: Link, unit: int, profiles: list[Profile]) -> Verdict | None:
    """The profile whose checks the unit matches best, or None when none matches."""
    ranked = identify(link, unit, profiles)
    return ranked[0] if ranked and ranked[0].outcome == MATCH else None


def choose(ranked: list[Verdict], port: str) -> Verdict:
    """The one profile a unit's answers match (identify's verdicts); ProfileNotFound listing the candidates, with
    what their checks met, when none or several match."""
    matches = [v for v in ranked if v.outcome == MATCH]
    if len(matches) == 1:
        return matches[0]
    unit = ranked[0].unit if ranked else 0
    if matches:
        listed = [(v.profile.id, ", ".join(v.reasons(FITS)[:2])) for v in matches]
        raise ProfileNotFound(unit, port, True, listed)
    listed = [(v.profile.id, (v.reasons(CONTRADICTS) or v.reasons(UNKNOWN) or ["no checks"])[0]) for v in ranked]
    raise ProfileNotFound(unit, port, False, listed)


def consistent(profile: Profile, answers: tuple[Answer, ...]) -> bool:
    """Whether answers read for another profile's checks could come from a drive with this profile's map: a value
    where it maps a readable entry (within the entry's range), exception 02 where it maps nothing."""
    for a in answers:
        entry = next((e for e in profile.entries if a.check.address in e.addresses), None)
        if a.raw is not None:
            if entry is None or not entry.readable:
                return False
            if a.check.words == 1 and entry.words == 1 and not entry.min <= a.raw <= entry.max:
                return False
        elif a.exception == 2 and entry is not None:
            return False
    return True


def confirm(drives: list[Drive], others: list[Profile] | None = None) -> list[Verdict]:
    """Check each drive against its profile before anything is written; IdentityMismatch (naming what answered
    and the shipped profile that fits better) on a contradiction. Returns the verdicts (inconclusive ones are for
    a warning)."""
    verdicts: list[Verdict] = []
    for drive in drives:
        verdict = probe(drive.link, drive.unit, drive.profile)
        if verdict.outcome == MISMATCH:
            pool = others if others is not None else shipped_profiles()
            # Only profiles whose map agrees with what was already answered are worth their own reads.
            pool = [p for p in pool if p.id != drive.profile.id and consistent(p, verdict.answers)]
            better = best_fit(drive.link, drive.unit, pool)
            raise IdentityMismatch(
                drive.profile.id,
                drive.profile.model,
                drive.unit,
                verdict.reasons(CONTRADICTS),
                (better.profile.id, better.profile.model) if better else None,
            )
        verdicts.append(verdict)
    return verdicts


def warning_text(verdicts: list[Verdict]) -> str | None:
    """One line for the drives whose identity could not be confirmed, or None."""
    unsure = [v for v in verdicts if v.outcome == INCONCLUSIVE]
    if not unsure:
        return None
    parts = []
    for v in unsure:
        why = "; ".join(v.reasons(UNKNOWN)) if v.answers else f"profile {v.profile.id} names no identity checks"
        parts.append(f"unit {v.unit} ({why})")
    first = unsure[0].profile
    return f"cannot confirm that the drive is a {first.model} (profile {first.id}): {', '.join(parts)}; going on"
