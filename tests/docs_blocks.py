"""The fenced blocks of README.md and docs/pages/, and how the tests run them (STYLE habit 11).

Every block has a language.  ``sh`` blocks are commands: the tests run each page's blocks in
order, in a temporary folder of that page, with bash (``set -e -o pipefail``: a failing line
fails the block; background jobs are waited for and their status counts).  ``toml`` blocks are
files the page's commands use: each is written into the page's folder under its name and loaded
as a scene.  ``python`` blocks are compiled; ``text`` blocks (diagrams, listings) are left alone,
unless a line of one reads like a command.

A block is tuned by HTML comments on the lines right above its fence (invisible on GitHub and
on the site), ``<!-- docs-test: KIND: VALUE -->``:

* ``small: rtsar run --duration 1; python tools/sim_cost.py --pulses 400``: a long block run
  at a small size: every command of the block that starts with those words gets the extra
  arguments appended (argparse takes the last of a repeated option);
* ``skip: REASON``: not run; the reason is printed in the test summary;
* ``needs: NAME``: run only where NAME is available (REQUIREMENTS), else skipped with the reason;
* ``file: NAME``: a toml block's file name (required for toml blocks);
* ``timeout: SECONDS``: the block's limit (default 120 s).

So that runs never collide with another process on this machine, every loopback port written
in a page (``127.0.0.1:NNNN``) is replaced by a free port for that page, and rtsar's default
endpoint (tcp://127.0.0.1:5555) by the page's own port for 5555 (``docs_shim.py``).
``python tools/X.py`` runs a copy of the repository's ``tools/`` in the page's folder, so a
script's outputs never land in the repository.
"""

from __future__ import annotations

import json
import os
import re
import shutil
import signal
import subprocess
import sys
from dataclasses import dataclass, field
from pathlib import Path

from conftest import free_port as _conftest_free_port

try:
    import tomllib
except ModuleNotFoundError:  # Python 3.10
    import tomli as tomllib

ROOT = Path(__file__).resolve().parents[1]
PAGES_DIR = ROOT / "docs" / "pages"
SHIM = Path(__file__).resolve().parent / "docs_shim.py"
LANGUAGES = ("sh", "toml", "python", "text")
KINDS = ("small", "skip", "needs", "file", "timeout")
DEFAULT_TIMEOUT_S = 120.0
COMMAND_WORDS = re.compile(r"^\s*(rtsar|python3?|pip|\.venv/bin/\w+|/usr/bin/python3)\s")


def pages() -> list[Path]:
    """README.md, then every page of the docs site, in a stable order."""
    return [ROOT / "README.md", *sorted(PAGES_DIR.rglob("*.md"))]


def page_name(page: Path) -> str:
    return page.relative_to(ROOT).as_posix()


def gnuradio_missing() -> str | None:
    """Why the GNU Radio block cannot run here (None when /usr/bin/python3 has GNU Radio)."""
    python = Path("/usr/bin/python3")
    if not python.exists():
        return "needs GNU Radio's Python (/usr/bin/python3 with gnuradio): not on this machine"
    done = subprocess.run(
        [str(python), "-c", "import gnuradio.zeromq"], capture_output=True, timeout=60
    )
    if done.returncode != 0:
        return "needs GNU Radio (Debian: apt-get install gnuradio): not installed here"
    return None


REQUIREMENTS = {"gnuradio": gnuradio_missing}


@dataclass
class Block:
    page: Path
    line: int  # 1-based line of the opening fence
    lang: str
    text: str
    directives: dict[str, str] = field(default_factory=dict)

    @property
    def where(self) -> str:
        return f"{page_name(self.page)}:{self.line}"

    def small(self) -> list[tuple[list[str], list[str]]]:
        """(command prefix words, extra arguments) of a ``small:`` directive."""
        out = []
        for item in self.directives.get("small", "").split(";"):
            words = item.split()
            if not words:
                continue
            cut = next((i for i, w in enumerate(words) if w.startswith("-")), len(words))
            if cut < 2 or cut == len(words):
                raise ValueError(f"{self.where}: small: '{item.strip()}' needs COMMAND... --OPTION")
            out.append((words[:cut], words[cut:]))
        return out


FENCE = re.compile(r"^```(\S*)\s*$")
DIRECTIVE = re.compile(r"^<!-- docs-test: (\w+):\s*(.*?)\s*-->\s*$")


def parse_blocks(page: Path) -> list[Block]:
    """The fenced blocks of a page with their directives; raises ValueError on a malformed page
    (an unlabelled or unknown language, an unknown directive, an unclosed fence)."""
    lines = page.read_text(encoding="utf-8").splitlines()
    blocks: list[Block] = []
    i = 0
    while i < len(lines):
        m = FENCE.match(lines[i])
        if not m:
            if lines[i].startswith("<!-- docs-test") and not DIRECTIVE.match(lines[i]):
                raise ValueError(f"{page_name(page)}:{i + 1}: malformed directive {lines[i]!r}")
            i += 1
            continue
        lang, start = m.group(1), i
        if lang not in LANGUAGES:
            raise ValueError(
                f"{page_name(page)}:{i + 1}: a fenced block needs one of the languages "
                f"{', '.join(LANGUAGES)} (sh blocks are run by the tests), got {lang or 'none'!r}"
            )
        directives = {}
        j = start - 1
        while j >= 0 and (d := DIRECTIVE.match(lines[j])):
            kind, value = d.groups()
            if kind not in KINDS:
                raise ValueError(f"{page_name(page)}:{j + 1}: unknown directive {kind!r}")
            directives[kind] = value
            j -= 1
        end = start + 1
        while end < len(lines) and lines[end].rstrip() != "```":
            end += 1
        if end == len(lines):
            raise ValueError(f"{page_name(page)}:{start + 1}: the block is never closed")
        body = "\n".join(lines[start + 1 : end]) + "\n"
        blocks.append(Block(page, start + 1, lang, body, directives))
        i = end + 1
    return blocks


def check_block(block: Block) -> None:
    """The rules every block obeys, whatever it runs; raises ValueError naming the block."""
    d = block.directives
    if block.lang == "toml" and "file" not in d:
        raise ValueError(f"{block.where}: a toml block needs <!-- docs-test: file: NAME.toml -->")
    if block.lang != "toml" and "file" in d:
        raise ValueError(f"{block.where}: file: is for toml blocks")
    if block.lang != "sh" and set(d) & {"small", "skip", "needs", "timeout"}:
        raise ValueError(f"{block.where}: {sorted(d)} only apply to sh blocks")
    if "needs" in d and d["needs"] not in REQUIREMENTS:
        raise ValueError(f"{block.where}: needs: one of {sorted(REQUIREMENTS)}")
    if "skip" in d and not d["skip"]:
        raise ValueError(f"{block.where}: skip: needs its reason")
    block.small()  # raises on a malformed one
    if block.lang == "text":
        for k, ln in enumerate(block.text.splitlines()):
            if COMMAND_WORDS.match(ln):
                raise ValueError(
                    f"{block.where}: line {k + 1} of a text block reads like a command "
                    f"({ln.strip()!r}): label the block sh so the tests run it"
                )


def free_port() -> int:
    return _conftest_free_port()


PORT = re.compile(r"\b(127\.0\.0\.1|localhost|0\.0\.0\.0):(\d{2,5})\b")


class PageRun:
    """Runs the blocks of one page, in order, in ``folder``."""

    def __init__(self, page: Path, folder: Path):
        self.page, self.folder = page, folder
        self.ports: dict[str, int] = {"5555": free_port()}
        self.bin = folder / ".docs-bin"
        self.bin.mkdir(parents=True)
        shutil.copytree(ROOT / "tools", folder / "tools", ignore=shutil.ignore_patterns("*.pyc"))
        for name in ("rtsar", "python", "python3"):
            shim = self.bin / name
            shim.write_text(f'#!/bin/sh\nexec "{sys.executable}" "{SHIM}" {name} "$@"\n')
            shim.chmod(0o755)

    def remap_ports(self, text: str) -> str:
        def repl(m):
            host, port = m.groups()
            if port not in self.ports:
                self.ports[port] = free_port()
            return f"{host}:{self.ports[port]}"

        return PORT.sub(repl, text)

    def write_file(self, block: Block) -> Path:
        path = self.folder / block.directives["file"]
        path.write_text(block.text, encoding="utf-8")
        return path

    def run_sh(self, block: Block) -> subprocess.CompletedProcess:
        script = (
            "set -e -o pipefail\n"
            + self.remap_ports(block.text)
            + '\nfor job in $(jobs -p); do wait "$job"; done\n'
        )
        env = dict(os.environ)
        env["PATH"] = os.pathsep.join([str(self.bin), env.get("PATH", "")])
        env["MPLBACKEND"] = "Agg"
        env["DOCS_TEST_CONFIG"] = json.dumps(
            {
                "small": block.small(),
                "endpoint": f"tcp://127.0.0.1:{self.ports['5555']}",
                "python": sys.executable,
            }
        )
        timeout = float(block.directives.get("timeout", DEFAULT_TIMEOUT_S))
        # Output to a file, not a pipe: a background job the block left behind (after a
        # failed command under set -e) would hold a pipe open until the time limit.
        log_path = self.folder / ".docs-block.log"
        with open(log_path, "w", encoding="utf-8") as log:
            proc = subprocess.Popen(
                ["bash", "-c", script],
                cwd=self.folder,
                env=env,
                stdout=log,
                stderr=subprocess.STDOUT,
                text=True,
                start_new_session=True,
            )
            try:
                proc.wait(timeout=timeout)
                timed_out = False
            except subprocess.TimeoutExpired:
                timed_out = True
            finally:
                try:  # whatever the block left running in the background
                    os.killpg(proc.pid, signal.SIGKILL)
                except ProcessLookupError:
                    pass
                proc.wait()
        out = log_path.read_text(encoding="utf-8", errors="replace")
        log_path.unlink()
        if timed_out:
            out += f"\n[docs test: the block ran past its {timeout:g} s limit and was killed]"
            return subprocess.CompletedProcess(proc.args, 124, out, "")
        return subprocess.CompletedProcess(proc.args, proc.returncode, out, "")


def load_toml_scene(path: Path) -> None:
    """Load a toml block as rtsar loads a scene file (a spotlight scene where it has
    [spotlight] or the crouch-spotlight preset); raises what rtsar would report."""
    table = tomllib.loads(path.read_text(encoding="utf-8"))
    if "spotlight" in table or table.get("preset") == "crouch-spotlight":
        from rtsar.spot.scene import load_spot_scene

        load_spot_scene(path)
    else:
        from rtsar.scene.files import load_scene

        load_scene(path)
