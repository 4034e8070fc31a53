"""`tune inertia` through the CLI in real time, judged with margins a loaded 2-core CI holds (issue 31 item 8).

On a busy host the client stalls for 0.1-2 s now and then: a host-timed move runs on, the sampling rate falls to a
sixth, and an identification that passes on an idle machine is refused, stopped at the travel limit, or accepted a
few % off with too tight an uncertainty (bench/inertia_accuracy.py --realtime measures how often). What a real-time
CLI test can hold under any load is the contract: the outcome is one of those, said in words that name their cause,
in JSON that agrees with the exit code; an accepted result is near the truth. Whether it is within its stated 3 sigma
is judged on virtual time, where the same code runs without the host's luck (each test names its virtual twin).

A test that needs the run accepted to judge what follows (what is written, shown, kept) asserts that it was, after
running it again as its words ask (NEEDED_ATTEMPTS): its machine and travel are ones a loaded host still identifies.
Nothing here skips: a run a loaded host left refused is a failure, said with its words.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import yaml

# A stall the product names asks the user to run it again: so does the test, this many times in all.
ATTEMPTS = 2
# ... and this many where the test needs the run accepted to judge what follows: with two CPU burners beside two test
# workers and other work on the machine (load 8), two plans were stopped twice in a row by 0.6-1.5 s stalls (the
# travel run past, DSX7E's 500 ms watchdog starved), each named as such.
NEEDED_ATTEMPTS = 3
STALL_WORDS = ("the host stalled", "the host was late")
# What a loaded host alone makes of a run that passes on an idle one: a stall named, or the slower sampling's
# uncertainty. A run that ends with these is run again (as a user would), up to ATTEMPTS times in all.
LOADED_WORDS = (*STALL_WORDS, "sampling gaps", "too uncertain", "too little acceleration", "inertia differs")
# How the stop's last line says that the drive latched an alarm (its watchdog's, after a stall): a run again needs
# it cleared first, on every axis (a run stopped at the travel limit by a stall that also starved the watchdog named
# no alarm in its reason and left E25 latched: the next run refused to move; a plan's unit 2 kept its E25).
LATCHED = "latched (see 'servotool alarm')"
# The causes an honest refusal or stop may name on a loaded host (the host's stalls, what the slower sampling left
# too uncertain, mechanics the checks saw, the travel the line needs).
HONEST_WORDS = (
    *STALL_WORDS,
    "too uncertain",
    "too little acceleration",
    "inertia differs",
    "load varies over the travel",
    "resonance",
    "lost motion",
    "--travel",
)
# Causes a stall must never be blamed on (issue 31 item 3: the loop, a sign convention).
WRONG_WORDS = ("sign convention", "the loop overshoots")
# An accepted result in real time on a loaded host: J_total within this share of the truth (a loaded host's stalls
# leave a few % of bias the uncertainty does not always cover; the 3 sigma judgement is on virtual time).
LOADED_J_SHARE = 0.1


def tune_json(
    cli: Any, *args: str, honest: tuple[str, ...] = (), attempts: int = ATTEMPTS
) -> tuple[Any, dict[str, Any]]:
    """(result, its JSON) of `servotool ARGS --json`, run again (as the words ask a user) while the outcome is a host
    stall or what it left too uncertain (LOADED_WORDS, and `honest`: the causes the test's own machine has), up to
    `attempts` times in all; the contract checked on each (assert_said)."""
    for _attempt in range(attempts):
        r = cli(*args, "--json")
        data = assert_said(r, honest)
        if r.code == 0 or not any(w in data["reason"] for w in (*LOADED_WORDS, *honest)):
            break
        if LATCHED in r.err:  # the drive's watchdog stopped it: cleared first, as the user would
            assert cli(*args[: args.index("tune")], "alarm", "clear").code == 0
    return r, data


def tune_ok(cli: Any, *args: str) -> tuple[Any, dict[str, Any]]:
    """tune_json, where the test needs the run accepted to judge what follows: asserted accepted (its reason shown
    where every attempt ended refused)."""
    r, data = tune_json(cli, *args, attempts=NEEDED_ATTEMPTS)
    assert r.code == 0, f"refused in all {NEEDED_ATTEMPTS} runs: {data.get('reason')}"
    return r, data


def cli_ok(cli: Any, *args: str) -> Any:
    """`servotool ARGS` without --json that the test needs accepted: run again while it ends with what a loaded host
    alone makes of it (LOADED_WORDS, on stderr), up to NEEDED_ATTEMPTS times; asserted accepted."""
    for _attempt in range(NEEDED_ATTEMPTS):
        r = cli(*args)
        assert "Traceback" not in r.err, r.err
        if r.code == 0 or not any(w in r.err for w in LOADED_WORDS):
            break
        if LATCHED in r.err:  # the drive's watchdog stopped it: cleared first, as the user would
            assert cli(*args[: args.index("tune")], "alarm", "clear").code == 0
    assert r.code == 0, r.err
    return r


def assert_said(r: Any, honest: tuple[str, ...] = ()) -> dict[str, Any]:
    """The contract of a `tune inertia --json` run whatever the host's load: exit 0 with ok, or exit 1 with ok False,
    nothing written and a reason (also on stderr) that names an honest cause (HONEST_WORDS, or all of `honest`: the
    test machine's own mechanics) and no wrong one."""
    assert "Traceback" not in r.err, r.err
    assert r.code in (0, 1), (r.code, r.err)
    data = r.json()
    if "error" in data:  # a failure after the identification (a step check's rollback, an alarm): worded as an error
        assert r.code == 1 and data["error"]["message"][:60] in r.err, (data, r.err)
        data = {**data, "ok": False, "reason": data["error"]["message"]}
    assert data["ok"] is (r.code == 0), data
    if r.code == 1:
        reason = data["reason"]
        assert data.get("written", False) is False, data  # (an error's JSON says what it put back in its words)
        assert reason and reason[:60] in r.err, (reason, r.err)
        assert any(w in reason for w in HONEST_WORDS) or (honest and all(w in reason for w in honest)), reason
        assert not any(w in reason for w in WRONG_WORDS), reason
    return data


def near(data: dict[str, Any], truth: float) -> bool:
    """Whether an accepted load ratio is within LOADED_J_SHARE of the truth's J_total, or within its own 3 sigma."""
    off = abs(data["ratio"] - truth)
    return off <= max(3 * (data.get("ratio_std") or 0.0), LOADED_J_SHARE * (1.0 + truth))


def run_plan(cli: Any, *args: str) -> Any:
    """`servotool run ARGS` whose tune steps run in real time: run again while it failed with what a loaded host
    alone makes of a tune step (LOADED_WORDS), up to NEEDED_ATTEMPTS times (a plan's tune steps are what it is run
    for). The last run is returned for the test to judge (its exit code first: nothing skips)."""
    for attempt in range(NEEDED_ATTEMPTS):
        r = cli("run", *args)
        r.attempts = attempt + 1  # a run after the first finds what the first one set already set
        assert "Traceback" not in r.err, r.err
        if r.code == 0 or not any(w in r.out + r.err for w in LOADED_WORDS):
            break
        if LATCHED in r.err:  # a drive's watchdog stopped a step: cleared on every axis first, as the user would
            plan = yaml.safe_load(Path(args[0]).read_text(encoding="utf-8"))
            for unit in plan.get("units", [1]):
                clear = ("--port", "sim", "-P", plan.get("profile", "dsx7e"), "--unit", str(unit), "alarm", "clear")
                assert cli(*clear).code == 0
    return r
