"""The README's transcripts, run again: every ```text block of `$ command` lines is replayed on a fresh simulated
drive and its output written back under each command, so what the README shows is what the current code prints.

    python man/transcripts.py            # rewrite README.md's transcripts
    python man/transcripts.py --check    # exit 1 (with a diff) where README.md's would change

A block runs in order in one throw-away folder with its own simulated drives, backups and config (HOME points
there; its path is shown as /home/me), at 100 columns. `$ cat FILE` shows a file the block goes on to use: its
content is the README's own, written to FILE before the next command. --check compares with every number masked:
identification figures and timings differ from run to run, wording and lines may not.
"""

from __future__ import annotations

import argparse
import difflib
import os
import re
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
README = ROOT / "README.md"
BLOCK = re.compile(r"```text\n(.*?)```", re.S)
SHOWN_HOME = "/home/me"
COLUMNS = 110


def commands(block: str) -> list[tuple[str, list[str]]]:
    """The block's commands, each with the output lines the README shows under it."""
    out: list[tuple[str, list[str]]] = []
    for line in block.splitlines():
        if line.startswith("$ "):
            out.append((line[2:], []))
        elif out:
            out[-1][1].append(line)
    return out


def replay(block: str) -> str:
    """The block as the current code prints it."""
    with tempfile.TemporaryDirectory(prefix="servotool-transcript-") as tmp:
        home = Path(tmp) / "home" / "me"
        work = home / "work"
        work.mkdir(parents=True)
        env = {k: v for k, v in os.environ.items() if not k.startswith(("SERVOTOOL_", "XDG_"))}
        env.update(HOME=str(home), COLUMNS=str(COLUMNS), PATH=_path_with_servotool(Path(tmp)))
        lines: list[str] = []
        for command, shown in commands(block):
            lines.append(f"$ {command}")
            if command.startswith("cat "):  # a file the block uses: the README's own content
                (work / command[4:].strip()).write_text("\n".join(shown) + "\n", encoding="utf-8")
                lines += shown
                continue
            done = subprocess.run(
                ["sh", "-c", f"{command} 2>&1"], cwd=work, env=env, capture_output=True, text=True, timeout=600
            )
            text = done.stdout.replace(str(home), SHOWN_HOME)
            lines += [row.rstrip() for row in text.rstrip("\n").splitlines()]
        return "\n".join(lines) + "\n"


def _path_with_servotool(tmp: Path) -> str:
    """PATH with a `servotool` that runs this checkout's package under this interpreter."""
    bin_dir = tmp / "bin"
    bin_dir.mkdir()
    script = bin_dir / "servotool"
    script.write_text(f'#!/bin/sh\nexec "{sys.executable}" -m servotool "$@"\n', encoding="utf-8")
    script.chmod(0o755)
    return f"{bin_dir}{os.pathsep}{os.environ.get('PATH', '')}"


def masked(text: str) -> str:
    """Numbers as #, runs of table padding as one space, wrapped lines joined, a frame's bytes as #, an
    identification's move lines left out (it stops once its estimate is tight: a move more or less), a sampling
    gap's mention and the subsets' notes (a widened uncertainty, an off-model spread) dropped: what may differ from
    run to run."""
    text = re.sub(r"(?m)^move \d+/\d+ (forward|reverse) at .*\n", "", text)
    text = re.sub(r"(?m)^(<<|>>)( [0-9a-f]{2})+", r"\1 #", text)
    text = re.sub(r"[-−+]?\d+(\.\d+)?(e[-+]?\d+)?", "#", text)  # a sign too: a speed reads -1 or 0 rpm at rest
    text = text.replace(", longest gap # ms", "")  # said only when the host left a gap in the sampling
    text = re.sub(r"[ ─━]+", " ", text)
    text = re.sub(r"\n (?=\S)", " ", text)  # a wrapped line joined: where it wraps follows the numbers' widths
    text = re.sub(r"(?m)^sampling gaps of up to # ms while the axis moved .*\n", "", text)  # a stall's note, too
    # the subsets' notes: whether the spread of J over the accelerations, the phases or the travel exceeds what the
    # speed noise makes is the noise's (a rigid load's thirds of the travel disagree 1.5x their uncertainty and 3 %
    # now and then: the README's own run said "off-model: inertia differs over the travel" once in CI)
    text = re.sub(r"(?m)^uncertainty widened #x: .*\n", "", text)
    return re.sub(r"(?m)^off-model: inertia differs .*; uncertainty widened to the spread .*\n", "", text)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--check", action="store_true", help="compare (numbers masked) instead of rewriting")
    args = parser.parse_args()
    readme = README.read_text(encoding="utf-8")
    fresh = BLOCK.sub(lambda m: f"```text\n{replay(m.group(1))}```", readme)
    if not args.check:
        README.write_text(fresh, encoding="utf-8")
        print(f"wrote {README}")
        return 0
    if masked(fresh) == masked(readme):
        return 0
    old, new = (re.findall(BLOCK, t) for t in (readme, fresh))
    for a, b in zip(old, new, strict=True):
        if masked(a) != masked(b):  # the lines that differ beyond the masked numbers, shown as masked
            lines = (masked(t).splitlines(True) for t in (a, b))
            sys.stdout.writelines(difflib.unified_diff(*lines, "README.md (masked)", "now (masked)"))
    print("README.md's transcripts differ from what the code prints: python man/transcripts.py rewrites them")
    return 1


if __name__ == "__main__":
    sys.exit(main())
