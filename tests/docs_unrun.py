"""What a docs block that is not run (``skip:``, or ``needs:`` where the need is missing) must
still be: every command in it real, with options its parser takes, every pip extra one that
pyproject.toml declares, every script and module one that exists.

Issue 39: a skipped block could say anything (``.[opencl-cpu]`` changed to ``.[opencl-gpu]`` in
the getting-started page passed).  Nothing is run here: rtsar's command lines go through the
command's own parser (options, choices, types), pip's through pyproject's extras.
"""

from __future__ import annotations

import contextlib
import importlib.util
import io
import re
import shlex
from pathlib import Path

from docs_blocks import ROOT, tomllib

OPERATORS = {"&&", "||", ";", "|", "&", ";;"}
REDIRECTS = {">", ">>", "<", ">&", "&>", "<&", ">|"}


def simple_commands(text: str) -> list[list[str]]:
    """The block's simple commands, each as its words (comments, continuations, redirections
    and the shell's joining operators taken away)."""
    out = []
    for line in re.sub(r"\\\n", " ", text).splitlines():
        lex = shlex.shlex(line, posix=True, punctuation_chars=True)
        lex.whitespace_split = True
        words: list[str] = []
        tokens = iter(list(lex))
        for tok in tokens:
            if tok in OPERATORS:
                out.append(words)
                words = []
            elif tok in REDIRECTS:
                if words and words[-1].isdigit():  # 2>&1: the descriptor goes with it
                    words.pop()
                next(tokens, None)
            else:
                words.append(tok)
        out.append(words)
    commands = []
    for words in out:
        while words and re.match(r"^[A-Z_][A-Z0-9_]*=", words[0]):  # VAR=value prefixes
            words = words[1:]
        if words:
            commands.append(words)
    return commands


def extras() -> set[str]:
    project = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))["project"]
    return set(project.get("optional-dependencies", {}))


def problems(words: list[str], parser_for) -> list[str]:
    """Why one command could not run as written (empty when it could)."""
    program, args = Path(words[0]).name, words[1:]
    if program == "rtsar":
        if not args:
            return []
        parser = parser_for(args[0])
        with contextlib.redirect_stderr(io.StringIO()) as err:
            try:
                parser.parse_args(args)
            except SystemExit as stop:
                if stop.code:
                    return [f"`{shlex.join(words)}`: {err.getvalue().strip().splitlines()[-1]}"]
        return []
    if program == "pip" or args[:2] == ["-m", "pip"]:
        named = [a for a in args if "[" in a]
        found = []
        for a in named:
            inner = a[a.index("[") + 1 : a.rindex("]")]
            found += [f"`{a}`: no extra {e!r} in pyproject.toml" for e in inner.split(",")
                      if e.strip() not in extras()]  # fmt: skip
        return found
    if program.startswith("python"):
        if args[:1] == ["-m"] and len(args) > 1:
            if args[1] != "venv" and importlib.util.find_spec(args[1]) is None:
                return [f"`{shlex.join(words)}`: no module {args[1]!r} here"]
            return []
        if args and args[0].endswith(".py") and not (ROOT / args[0]).is_file():
            return [f"`{shlex.join(words)}`: no script {args[0]} in the repository"]
    return []
