"""Shell completion of what the profile knows: codes, groups, profile ids (`--install-completion` sets it up).

Completers never fail: with no profile to be found they offer nothing.
"""

from __future__ import annotations

from typing import Any

from servotool.model.lookup import COMMON_GROUPS


def _profile(ctx: Any) -> Any:
    from servotool.connection import ConnectOptions, resolve

    root = ctx.find_root() if ctx is not None else None
    given = (root.params.get("profile") if root is not None else None) or None
    port = (root.params.get("port") if root is not None else None) or None
    try:
        return resolve(ConnectOptions(profile=given, port=port), need_port=False).profile
    except Exception:
        return None


def codes(ctx: Any, incomplete: str) -> list[tuple[str, str]]:
    """Entry codes (and their names) starting with what was typed."""
    profile = _profile(ctx)
    if profile is None:
        return []
    typed = incomplete.upper()
    return [(e.code, e.name) for e in profile.entries if e.code.upper().startswith(typed)]


def assignments(ctx: Any, incomplete: str) -> list[tuple[str, str]]:
    """CODE= for settable parameters."""
    if "=" in incomplete:
        return []
    return [(f"{code}=", name) for code, name in codes(ctx, incomplete) if not code.startswith(("Un", "Fn"))]


def groups(ctx: Any, incomplete: str) -> list[str]:
    profile = _profile(ctx)
    own = {e.group for e in profile.entries if e.group} if profile is not None else set()
    return sorted(g for g in own | set(COMMON_GROUPS) if g.lower().startswith(incomplete.lower()))


def profiles(incomplete: str) -> list[str]:
    from servotool.model.loader import builtin_ids

    return [p for p in builtin_ids() if p.startswith(incomplete.lower())]
