"""Mutation probe: does the suite catch small, plausible bugs?  (issue 39)

Each mutant in ``tools/mutants.toml`` is one edit of one file (``before`` → ``after``, which
must occur exactly once).  For each, the probe writes the edit into a scratch git worktree of
the committed HEAD, runs the mutant's ``tests`` there with pytest (``-x``, one process, CI=true,
PYTHONPATH set so that in-process imports and the ``rtsar`` commands the tests start both load
the worktree's code), and calls the mutant *caught* when a test fails that passes again once
the file is restored, *survived* when all pass.  Exit status 1 if any was not caught.  Prints a
Markdown table (``--out`` writes it too).

    python tools/mutation_probe.py                       # every mutant of the list
    python tools/mutation_probe.py --only sicd-sgn       # one (or several) by name
    python tools/mutation_probe.py --full-suite          # survivors again on all of tests/ (-n 2)

Before the mutants run, a sanity mutant (the package's ``__init__`` raising) must fail the
first mutant's tests, and a Python started outside the worktree (as the tests' ``rtsar``
commands are) must fail to import it: otherwise the tests are not loading the worktree and
every verdict would be false.
"""

from __future__ import annotations

import argparse
import os
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

try:
    import tomllib
except ModuleNotFoundError:  # Python 3.10
    import tomli as tomllib

ROOT = Path(__file__).resolve().parents[1]
DEFAULT_LIST = ROOT / "tools" / "mutants.toml"
SANITY = ("rtsar/__init__.py", 'raise RuntimeError("mutation probe sanity mutant")\n')


def load_mutants(path: Path) -> list[dict]:
    with open(path, "rb") as f:
        mutants = tomllib.load(f).get("mutant", [])
    names = [m.get("name") for m in mutants]
    for m in mutants:
        missing = [k for k in ("name", "file", "before", "after", "tests") if k not in m]
        if missing:
            raise SystemExit(f"{path}: mutant {m.get('name', '?')!r} lacks {', '.join(missing)}")
    duplicates = sorted({n for n in names if names.count(n) > 1})
    if duplicates:
        raise SystemExit(f"{path}: mutant names used twice: {', '.join(duplicates)}")
    return mutants


def apply(tree: Path, mutant: dict) -> str | None:
    """Write the mutant into ``tree``; None, or why it cannot be applied."""
    path = tree / mutant["file"]
    if not path.is_file():
        return f"no file {mutant['file']}"
    text = path.read_text(encoding="utf-8")
    found = text.count(mutant["before"])
    if found != 1:
        return f"'before' occurs {found} times in {mutant['file']} (must be once)"
    path.write_text(text.replace(mutant["before"], mutant["after"]), encoding="utf-8")
    return None


def restore(tree: Path, file: str) -> None:
    subprocess.run(["git", "-C", str(tree), "checkout", "--", file], check=True)


def run_tests(tree: Path, tests: list[str], workers: int = 0) -> tuple[str, str, float]:
    """(verdict, the first failing test or the reason, seconds): caught, survived or error."""
    cmd = [sys.executable, "-m", "pytest", "-q", "-x", "-p", "no:cacheprovider", "-rf"]
    cmd += ["-n", str(workers)] if workers else ["-p", "no:xdist"]
    env = dict(os.environ, CI="true", PYTHONPATH=str(tree))
    t0 = time.perf_counter()
    done = subprocess.run(cmd + tests, cwd=tree, env=env, capture_output=True, text=True)
    seconds = time.perf_counter() - t0
    failed = re.findall(r"^(?:FAILED|ERROR) (\S+)", done.stdout, re.MULTILINE)
    if done.returncode == 0:
        return "survived", "", seconds
    if done.returncode == 1:
        return "caught", failed[0] if failed else "(a failure)", seconds
    tail = (done.stdout + done.stderr).strip().splitlines()[-1:] or ["?"]
    return "error", f"pytest exit {done.returncode}: {tail[0][:120]}", seconds


def probe(mutants: list[dict], full_suite: bool, say=print) -> list[dict]:
    rows = []
    with tempfile.TemporaryDirectory(prefix="rtsar-mutants-") as scratch:
        tree = Path(scratch) / "tree"
        subprocess.run(
            ["git", "-C", str(ROOT), "worktree", "add", "--detach", "-q", str(tree), "HEAD"],
            check=True,
        )
        shared = ROOT.parent / "shared"  # the papers and data beside the checkout
        if shared.is_dir():
            (Path(scratch) / "shared").symlink_to(shared)  # else its tests fail under CI=true
        try:
            sanity_file, line = SANITY
            (tree / sanity_file).write_text(line, encoding="utf-8")
            verdict, _, _ = run_tests(tree, mutants[0]["tests"])
            elsewhere = subprocess.run(  # as the tests' `rtsar` commands import it: no cwd
                [sys.executable, "-c", "import rtsar"],
                cwd=scratch,
                env=dict(os.environ, PYTHONPATH=str(tree)),
                capture_output=True,
            )
            restore(tree, sanity_file)
            if verdict == "survived" or elsewhere.returncode == 0:
                raise SystemExit(
                    "the sanity mutant was not caught: the tests do not load the worktree's "
                    "code (an editable install ahead of PYTHONPATH?), so no verdict would hold"
                )
            for i, m in enumerate(mutants, 1):
                why = apply(tree, m)
                if why is not None:
                    row = dict(m, verdict="stale", detail=why, seconds=0.0)
                else:
                    verdict, detail, seconds = run_tests(tree, m["tests"])
                    if verdict == "survived" and full_suite:
                        verdict, detail, more = run_tests(tree, ["tests"], workers=2)
                        seconds += more
                        detail = detail or "the whole suite passed"
                    restore(tree, m["file"])
                    if verdict == "caught" and "::" in detail:  # and not without the mutant
                        again, _, more = run_tests(tree, [detail])
                        seconds += more
                        if again != "survived":
                            verdict, detail = "error", f"{detail} fails without the mutant too"
                    row = dict(m, verdict=verdict, detail=detail, seconds=seconds)
                rows.append(row)
                say(f"[{i}/{len(mutants)}] {m['name']}: {row['verdict']} {row['detail']}")
        finally:
            subprocess.run(
                ["git", "-C", str(ROOT), "worktree", "remove", "--force", str(tree)], check=False
            )
    return rows


def table(rows: list[dict]) -> str:
    lines = [
        "| mutant | file | verdict | by | s |",
        "|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(
            f"| {r['name']} | `{r['file']}` | {r['verdict']} | {r['detail'] or '—'} "
            f"| {r['seconds']:.0f} |"
        )
    caught = sum(r["verdict"] == "caught" for r in rows)
    lines.append("")
    lines.append(f"{caught} of {len(rows)} caught")
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--list", type=Path, default=DEFAULT_LIST, help="the mutants (TOML)")
    ap.add_argument("--only", nargs="+", metavar="NAME", help="run these mutants only")
    ap.add_argument(
        "--full-suite", action="store_true", help="run a survivor again on all of tests/ (-n 2)"
    )
    ap.add_argument("--out", type=Path, help="also write the table here")
    args = ap.parse_args(argv)
    mutants = load_mutants(args.list)
    if args.only:
        unknown = sorted(set(args.only) - {m["name"] for m in mutants})
        if unknown:
            ap.error(f"no mutant named {', '.join(unknown)} in {args.list}")
        mutants = [m for m in mutants if m["name"] in args.only]
    rows = probe(mutants, args.full_suite)
    text = table(rows)
    print(text)
    if args.out:
        args.out.write_text(text + "\n", encoding="utf-8")
    return 1 if any(r["verdict"] != "caught" for r in rows) else 0


if __name__ == "__main__":
    sys.exit(main())
