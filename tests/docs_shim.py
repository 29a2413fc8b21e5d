"""``rtsar``, ``python`` and ``python3`` as the docs tests run them (tests/docs_blocks.py).

    docs_shim.py NAME ARGS...

Runs NAME with ARGS as written, with three changes, read from $DOCS_TEST_CONFIG (JSON):

* ``small``: [[prefix words, extra args], ...]: a command whose arguments start with the prefix
  (``run`` for ``rtsar run``, ``tools/sim_cost.py`` for ``python tools/sim_cost.py``) gets the
  extra arguments appended (argparse keeps the last of a repeated option);
* ``endpoint``: rtsar's default endpoint (tcp://127.0.0.1:5555) replaced by the page's own
  free port wherever a command would use it by default (run, replay, demo, spotlight
  --publish bind it; view, subscribe connect to it);
* ``python``: the interpreter of the test session, so ``rtsar`` and ``python`` are the
  environment under test.
"""

from __future__ import annotations

import json
import os
import sys
from pathlib import Path

BINDS = ("run", "replay", "demo")  # --endpoint ENDPOINT, default 5555
CONNECTS = ("view", "subscribe")  # [ENDPOINT] positional, default 5555


def with_endpoint(args: list[str], endpoint: str) -> list[str]:
    """rtsar ARGS with the default endpoint made explicit."""
    if not args:
        return args
    command, rest = args[0], args[1:]
    given = any(a == "--endpoint" or a.startswith("--endpoint=") for a in rest)
    if command in BINDS and not given:
        return [command, *rest, "--endpoint", endpoint]
    if command in CONNECTS and not any(a.startswith(("tcp://", "ipc://")) for a in rest):
        return [command, endpoint, *rest]
    if command == "spotlight":
        out = [command]
        for i, a in enumerate(rest):
            following = rest[i + 1] if i + 1 < len(rest) else ""
            if a == "--publish" and not following.startswith(("tcp://", "ipc://")):
                a = f"--publish={endpoint}"
            out.append(a)
        return out
    return args


def rewrite(name: str, args: list[str], config: dict) -> list[str]:
    """The argv to execute for ``NAME ARGS`` under ``config``."""
    args = list(args)
    for prefix, extra in config.get("small", []):
        if args[: len(prefix) - 1] == prefix[1:] and prefix[0] in (name, _alias(name)):
            args += extra
    python = config.get("python", sys.executable)
    if name == "rtsar":
        args = with_endpoint(args, config["endpoint"]) if "endpoint" in config else args
        script = Path(python).with_name("rtsar")
        return [str(script), *args] if script.exists() else [python, "-m", "rtsar", *args]
    return [python, *args]


def _alias(name: str) -> str:
    return {"python3": "python", "python": "python3"}.get(name, name)


def main() -> None:
    name, args = sys.argv[1], sys.argv[2:]
    config = json.loads(os.environ.get("DOCS_TEST_CONFIG", "{}"))
    argv = rewrite(name, args, config)
    os.execv(argv[0], argv)


if __name__ == "__main__":
    main()
