"""A profile's identity section: validating it, and the read requests its checks take (see profiles/SCHEMA.md)."""

from __future__ import annotations

from collections.abc import Collection
from typing import Any

from servotool.model.checker import Checker, shown
from servotool.model.profile import Entry, Identity, IdentityCheck, Limits, Profile

CHECK_KEYS = {"code", "address", "absent", "range", "sim", "source", "unverified"}


MAX_REQUESTS = 2  # the check runs before every command's first write: it must stay cheap


def read_plan(checks: tuple[IdentityCheck, ...], max_read: int) -> list[tuple[int, int, list[IdentityCheck]]]:
    """(address, count, checks) of each request: adjacent present checks share one read (within max_read); an
    address that must be absent is read alone, since its exception 02 would fail any block around it."""
    plans: list[tuple[int, int, list[IdentityCheck]]] = []
    for c in sorted(checks, key=lambda c: (c.absent, c.address)):
        if plans and not c.absent and not plans[-1][2][0].absent:
            start, count, group = plans[-1]
            if c.address == start + count and c.address + c.words - start <= max_read:
                plans[-1] = (start, count + c.words, [*group, c])
                continue
        plans.append((c.address, c.words, [c]))
    return plans


def parse_identity(
    chk: Checker, raw: Any, entries: dict[str, Entry], limits: Limits, broken: Collection[str] = ()
) -> Identity | None:
    """The `identity` mapping: {firmware, model, checks: [...]}; problems go to the checker. A check naming a
    broken entry (one of `broken`, upper-case codes) is left out without a problem of its own."""
    if not isinstance(raw, dict):
        chk.bad("identity", f"expected a mapping {{firmware, model, checks}}, got {shown(raw)}")
        return None
    chk.known_keys(raw, ("firmware", "model", "checks"), "identity")
    items = raw.get("checks")
    if not isinstance(items, list) or not items:
        chk.bad(
            "identity.checks", f"expected a non-empty list of {{code|address, range, sim, source}}, got {shown(items)}"
        )
        return None
    checks = [
        c for i, item in enumerate(items) if (c := _parse_check(chk, item, f"identity.checks[{i}]", entries, broken))
    ]
    checked = {c.code.upper() for c in checks if c.code}
    names: dict[str, str] = {}
    for key in ("firmware", "model"):
        if key not in raw or len(checks) < len(items):  # a broken check may be the one it names
            continue
        code = chk.need(raw, key, "identity", str)
        if code is None or code.upper() in broken:
            continue
        if code.upper() not in entries:
            chk.bad(f"identity.{key}", f"names unknown entry {shown(code)}")
        elif code.upper() not in checked:
            chk.bad(f"identity.{key}", f"{code} must also be one of the checks (they are what is read)")
        else:
            names[key] = entries[code.upper()].code
    addresses = [a for c in checks for a in range(c.address, c.address + c.words)]
    if len(addresses) != len(set(addresses)):
        chk.bad("identity.checks", "two checks read the same address")
    if len(checks) == len(items) and len(read_plan(tuple(checks), limits.max_read)) > MAX_REQUESTS:
        chk.bad(
            "identity.checks",
            f"take more than {MAX_REQUESTS} read requests: keep them at adjacent addresses "
            f"(at most {limits.max_read} registers a request)",
        )
    return Identity(tuple(checks), names.get("firmware", ""), names.get("model", ""))


def _parse_check(
    chk: Checker, item: Any, loc: str, entries: dict[str, Entry], broken: Collection[str]
) -> IdentityCheck | None:
    if not isinstance(item, dict):
        chk.bad(loc, f"expected a mapping, got {shown(item)}")
        return None
    chk.known_keys(item, CHECK_KEYS, loc)
    before = len(chk.problems)
    source = chk.need(item, "source", loc, str)
    unverified = chk.opt(item, "unverified", loc, str, "")
    absent = chk.opt(item, "absent", loc, bool, False)
    sim = chk.opt(item, "sim", loc, int, None)
    span = _range(chk, item["range"], f"{loc}.range") if "range" in item else None
    if ("code" in item) == ("address" in item):
        chk.bad(loc, "give either 'code' (an entry of this profile) or 'address' (one it does not have)")
        return None
    if "address" in item:
        address = chk.need(item, "address", loc, int)
        if address is not None and not 0 <= address <= 0xFFFF:
            chk.bad(f"{loc}.address", f"{address} is outside 0..65535")
        elif address is not None and any(address in e.addresses for e in entries.values()):
            chk.bad(f"{loc}.address", f"{address} belongs to an entry: check it by its code")
        if not absent or span is not None or sim is not None:
            chk.bad(loc, "a bare address is a check that the drive lacks it: 'absent: true', no range or sim")
        if len(chk.problems) > before or address is None or source is None:
            return None
        return IdentityCheck(address, 1, "", True, None, None, source, unverified)
    code = chk.need(item, "code", loc, str)
    entry = entries.get(str(code).upper()) if code is not None else None
    if code is not None and str(code).upper() in broken:
        return None
    if code is not None and entry is None:
        chk.bad(f"{loc}.code", f"names unknown entry {shown(code)}")
    if entry is not None:
        _check_entry(chk, f"{loc} ({entry.code})", entry, absent, span, sim)
    if len(chk.problems) > before or entry is None or source is None:
        return None
    return IdentityCheck(entry.address, entry.words, entry.code, False, span, sim, source, unverified)


def _check_entry(
    chk: Checker, loc: str, entry: Entry, absent: bool, span: tuple[int, int] | None, sim: int | None
) -> None:
    if not entry.readable:
        chk.bad(loc, f"{entry.code} is write-only and cannot be read")
    if absent:
        chk.bad(loc, "'absent' is for an address this map does not have, not for one of its entries")
    if span is not None and not entry.min <= span[0] <= span[1] <= entry.max:
        chk.bad(f"{loc}.range", f"{list(span)} is outside the entry's range {entry.min}..{entry.max}")
    if sim is not None:
        if entry.cls == "Pn":
            chk.bad(f"{loc}.sim", "a parameter answers its default on the simulator; 'sim' is for Sn/Un entries")
        elif span is not None and not span[0] <= sim <= span[1]:
            chk.bad(f"{loc}.sim", f"{sim} is outside the check's range {span[0]}..{span[1]}")
        elif not entry.min <= sim <= entry.max:
            chk.bad(f"{loc}.sim", f"{sim} is outside the entry's range {entry.min}..{entry.max}")
    elif (
        entry.cls == "Pn" and span is not None and entry.default is not None and not span[0] <= entry.default <= span[1]
    ):
        chk.bad(f"{loc}.range", f"the default {entry.default} (what the simulator answers) is outside it")


def _range(chk: Checker, raw: Any, loc: str) -> tuple[int, int] | None:
    ok = isinstance(raw, list) and len(raw) == 2 and all(isinstance(v, int) and not isinstance(v, bool) for v in raw)
    if not ok or raw[0] > raw[1]:
        chk.bad(loc, f"expected [lo, hi] raw values with lo <= hi, got {shown(raw)}")
        return None
    return raw[0], raw[1]


def identity_entries(profile: Profile) -> list[Entry]:
    """The entries that name a drive (a backup records them; the host's journal keys its records by them): those
    the profile's identity section checks (its firmware and model entries among them), in the section's order."""
    if profile.identity is None:
        return []
    codes = [c.code for c in profile.identity.checks if c.code]
    return [e for e in (profile.find(c) for c in codes) if e is not None and e.readable]
