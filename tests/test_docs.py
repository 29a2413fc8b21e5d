"""The documentation runs (issue 31; STYLE habit 11): README.md and every page of docs/pages/.

* every ``sh`` block is run as written, page by page, in a temporary folder (tests/docs_blocks.py
  says how, and how a long block is run small or skipped with its reason); a failing block
  fails here, with its page and line;
* every ``toml`` block is written where its page's commands find it and loaded as a scene;
* the site builds with ``mkdocs build --strict`` (a broken link, a missing page or anchor, a
  page left out of the navigation fails);
* the README fits a screen (at most 300 lines), keeps the two commands byte for byte, and its
  command table, like the reference's, names every ``rtsar`` command.
"""

from __future__ import annotations

import argparse
import os
import re
import shutil
import subprocess
import sys
import time
from pathlib import Path

import docs_shim
import pytest
from docs_blocks import (
    PAGES_DIR,
    REQUIREMENTS,
    ROOT,
    PageRun,
    check_block,
    load_toml_scene,
    page_name,
    pages,
    parse_blocks,
)

from rtsar.app.cli import build_parser, main

README = ROOT / "README.md"
COMMANDS_PAGE = PAGES_DIR / "reference" / "commands.md"
TWO_COMMANDS = (
    'python3 -m venv .venv && .venv/bin/pip install ".[opencl-cpu]" && .venv/bin/rtsar prepare'
    " && .venv/bin/rtsar run",
    'python3 -m venv .venv && .venv/bin/pip install ".[test]"'
    " && .venv/bin/python -m pytest -q -n auto",
)
# Each block's (where, outcome, seconds or reason) goes into its test's report under this key,
# for the summary (tests/conftest.py): in the report, it reaches the summary from a worker of
# pytest -n too.
DOCS_BLOCK = "docs_block"


def ci() -> bool:
    return os.environ.get("CI", "").strip().lower() in ("true", "1", "yes")


def runnable_pages() -> list[Path]:
    return [p for p in pages() if any(b.lang in ("sh", "toml") for b in parse_blocks(p))]


def test_every_block_follows_the_rules():
    """Languages on every fence, known directives, toml blocks named, no command in a text
    block (a command there would never run)."""
    problems = []
    for page in pages():
        try:
            for block in parse_blocks(page):
                check_block(block)
        except ValueError as exc:
            problems.append(str(exc))
    assert not problems, "\n".join(problems)


def test_there_are_blocks_to_run():
    blocks = [b for p in pages() for b in parse_blocks(p)]
    runnable = [b for b in blocks if b.lang == "sh" and not set(b.directives) & {"skip"}]
    assert len(runnable) >= 8 and any(b.page == README for b in runnable)


@pytest.mark.slow
@pytest.mark.parametrize("page", runnable_pages(), ids=page_name)
def test_the_page_runs_as_written(page, tmp_path, record_property):
    """The page's blocks in order, in one folder: a block may use what an earlier one made."""
    run = PageRun(page, tmp_path)
    for block in parse_blocks(page):
        if block.lang == "toml":
            path = run.write_file(block)
            try:
                load_toml_scene(path)
            except (ValueError, OSError, RuntimeError) as exc:
                pytest.fail(f"{block.where}: the scene {path.name} does not load: {exc}")
            continue
        if block.lang == "python":
            compile(block.text, block.where, "exec")
            continue
        if block.lang != "sh":
            continue
        reason = block.directives.get("skip")
        if reason is None and "needs" in block.directives:
            reason = REQUIREMENTS[block.directives["needs"]]()
            if reason and ci():  # CI installs what a block needs (.ci/run): none may go unrun
                pytest.fail(f"{block.where}: {reason} (CI=true: .ci/run installs it)")
        if reason:
            record_property(DOCS_BLOCK, (block.where, "skipped", reason))
            continue
        t0 = time.perf_counter()
        done = run.run_sh(block)
        seconds = time.perf_counter() - t0
        if done.returncode != 0:
            record_property(DOCS_BLOCK, (block.where, "FAILED", f"exit status {done.returncode}"))
            pytest.fail(
                f"{block.where} failed as written (exit status {done.returncode}):\n"
                f"{block.text}\n--- its output (last 3000 characters) ---\n"
                f"{done.stdout[-3000:]}"
            )
        record_property(DOCS_BLOCK, (block.where, "ran", f"{seconds:.1f} s"))


def test_blocks_not_run_still_name_real_commands_options_and_extras():
    """A skipped block is checked without running it (tests/docs_unrun.py): its rtsar command
    lines parse, its pip extras exist, its scripts and modules are there."""
    from docs_unrun import problems, simple_commands

    found, checked = [], 0
    for page in pages():
        for block in parse_blocks(page):
            if block.lang != "sh" or not set(block.directives) & {"skip", "needs"}:
                continue
            for words in simple_commands(block.text):
                checked += 1
                found += [f"{block.where}: {p}" for p in problems(words, build_parser)]
    assert checked >= 10, f"only {checked} commands in blocks not run: the parser lost them?"
    assert not found, "\n".join(found)


def test_the_unrun_check_catches_a_wrong_extra_option_and_script():
    from docs_unrun import problems, simple_commands

    block = (
        'python3 -m venv .venv && .venv/bin/pip install ".[opencl-gpu]" && .venv/bin/rtsar run\n'
        "rtsar view --http 8080 --no-such-option   # comment\n"
        "rtsar run --preset nope &\n"
        "python tools/no_such_tool.py --x 2>&1 | tail\n"
    )
    said = [p for words in simple_commands(block) for p in problems(words, build_parser)]
    assert len(said) == 4, said
    assert "opencl-gpu" in said[0] and "--no-such-option" in said[1]
    assert "nope" in said[2] and "no_such_tool.py" in said[3]


def test_the_readme_fits_a_screen_and_keeps_the_two_commands():
    lines = README.read_text(encoding="utf-8").splitlines()
    assert len(lines) <= 300, f"README.md has {len(lines)} lines: move text into docs/pages/"
    for command in TWO_COMMANDS:
        assert command in lines, f"README.md lost the line {command!r}"


def test_what_ci_runs_is_what_the_two_commands_install_and_run():
    """The two commands are skipped by the docs test (each installs an environment); what
    stands for them is checked here: .ci/run installs command 2's extra into a fresh
    environment and runs command 2's pytest; that extra includes command 1's (its OpenCL
    driver); and a README block runs command 1's `rtsar run` (shortened)."""
    from docs_blocks import tomllib

    ci_lines = (ROOT / ".ci" / "run").read_text(encoding="utf-8").splitlines()
    assert 'python -m pip install --quiet ".[test]"' in ci_lines
    assert ci_lines[-1] == "python -m pytest -q -n auto" and TWO_COMMANDS[1].endswith(
        " -m pytest -q -n auto"
    )
    extras = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"][
        "optional-dependencies"
    ]
    assert '".[opencl-cpu]"' in TWO_COMMANDS[0] and "rtsar[opencl-cpu]" in extras["test"]
    assert TWO_COMMANDS[0].endswith(".venv/bin/rtsar run")
    runs = [
        b for b in parse_blocks(README)
        if b.lang == "sh" and "skip" not in b.directives
        and any(line.startswith("rtsar run") for line in b.text.splitlines())
    ]  # fmt: skip
    assert runs, "no README block runs `rtsar run`"


def cli_commands() -> set[str]:
    parser = build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return set(sub.choices)


def table_commands(path: Path) -> set[str]:
    """Commands named at the start of a table row: ``| `rtsar NAME …` |``, also a second
    usage in the same cell (``…`, `rtsar NAME …``)."""
    out = set()
    for row in re.findall(r"^\| (`rtsar [^|]*)\|", path.read_text(encoding="utf-8"), re.M):
        out |= set(re.findall(r"`rtsar ([a-z0-9-]+)", row))
    return out


@pytest.mark.parametrize("path", [README, COMMANDS_PAGE], ids=page_name)
def test_the_command_tables_name_every_command(path):
    named, known = table_commands(path), cli_commands()
    assert named - known == set(), f"{page_name(path)} names commands rtsar lacks"
    assert known - named == set(), f"{page_name(path)}'s table lacks commands"


@pytest.mark.parametrize("name", sorted(table_commands(README)))
def test_every_command_of_the_table_has_help(name, capsys):
    with pytest.raises(SystemExit) as done:
        main([name, "--help"])
    assert done.value.code == 0 and capsys.readouterr().out.startswith(f"usage: rtsar {name}")


def test_the_readme_links_lead_somewhere():
    """Relative links and pictures of README.md (outside the site's strict build) exist."""
    text = README.read_text(encoding="utf-8")
    missing = []
    for target in re.findall(r"\]\(([^)\s]+)\)", text):
        if re.match(r"[a-z]+:", target):
            continue
        path = (ROOT / target.split("#")[0]).resolve()
        if not path.exists():
            missing.append(target)
    assert not missing, f"README.md links to missing files: {missing}"


def github_anchor(heading: str) -> str:
    """GitHub's anchor of a heading: lower case, punctuation but - and _ dropped, each space
    a hyphen (runs of them kept)."""
    return re.sub(r"[^\w\- ]", "", heading.strip().lower()).replace(" ", "-")


def test_every_heading_has_one_anchor_on_github_and_on_the_site():
    """The pages read the same on GitHub and on the site (docs/mkdocs.yml), anchors included:
    a cold review found `wire.md#instrument-frames-serial-tcp-input` (MkDocs) reaching the page
    but not the section on GitHub (`…serial--tcp-input`: "serial / TCP")."""
    from markdown.extensions.toc import slugify

    differ = []
    for page in [README, *pages()]:
        fenced = False
        for line in page.read_text(encoding="utf-8").splitlines():
            if line.startswith("```"):
                fenced = not fenced
            heading = None if fenced else re.match(r"#{1,6}\s+(.*?)\s*$", line)
            if heading:
                text = heading.group(1).replace("`", "")
                if slugify(text, "-") != github_anchor(text):
                    differ.append(f"{page.relative_to(ROOT)}: {heading.group(1)!r}")
    assert not differ, "headings whose anchors differ on GitHub and MkDocs:\n" + "\n".join(differ)


def mkdocs_build(config: Path, site: Path) -> subprocess.CompletedProcess:
    """``mkdocs build --strict`` (never -q: it hides the warnings that strict mode counts)."""
    try:
        import mkdocs  # noqa: F401
    except ImportError:
        message = 'mkdocs is not installed: pip install ".[docs]"'
        if ci():
            pytest.fail(message + " (CI must build the docs)")
        pytest.skip(message)
    return subprocess.run(
        [sys.executable, "-m", "mkdocs", "build", "--strict", "-f", str(config), "-d", str(site)],
        capture_output=True,
        text=True,
        timeout=300,
    )


def test_the_docs_site_builds_strict(tmp_path):
    """``mkdocs build --strict``: warnings (a broken link or anchor, a page not in the nav, a
    missing page) fail.  MkDocs comes with the docs extra (and the test extra)."""
    done = mkdocs_build(ROOT / "docs" / "mkdocs.yml", tmp_path / "site")
    assert done.returncode == 0, f"mkdocs build --strict failed:\n{done.stdout}{done.stderr}"
    assert (tmp_path / "site" / "index.html").is_file()


@pytest.mark.parametrize(
    "breakage",
    ["[a lost page](guide/no-such-page.md)", "[a lost anchor](guide/start.md#no-such-anchor)"],
)
def test_the_strict_build_fails_on_a_broken_link(tmp_path, breakage):
    """The check above can fail: the same site with one broken link does not build."""
    shutil.copytree(ROOT / "docs", tmp_path / "docs", ignore=shutil.ignore_patterns("site"))
    index = tmp_path / "docs" / "pages" / "index.md"
    index.write_text(index.read_text(encoding="utf-8") + f"\n{breakage}\n", encoding="utf-8")
    done = mkdocs_build(tmp_path / "docs" / "mkdocs.yml", tmp_path / "site")
    assert done.returncode != 0 and "strict" in done.stdout + done.stderr


def test_every_page_is_reachable_from_the_readme_or_the_index():
    """A page nobody links to is lost (the nav is checked by the strict build)."""
    text = README.read_text(encoding="utf-8") + (PAGES_DIR / "index.md").read_text("utf-8")
    lost = [
        page_name(p)
        for p in sorted(PAGES_DIR.rglob("*.md"))
        if p.name != "index.md" and p.relative_to(PAGES_DIR).as_posix() not in text
    ]
    assert not lost, f"pages linked from neither README.md nor docs/pages/index.md: {lost}"


def test_code_points_to_pages_that_exist():
    """Messages and docstrings that send a user to the docs name pages that exist, and none
    sends them to a README section that moved away."""
    readme = README.read_text(encoding="utf-8")
    headings = {h.strip() for h in re.findall(r"^#+ (.*)$", readme, re.M)}
    problems = []
    for path in sorted((ROOT / "rtsar").rglob("*.py")) + sorted((ROOT / "tools").glob("*.py")):
        text = path.read_text(encoding="utf-8")
        for page in re.findall(r"docs/pages/[\w/.-]+\.md", text):
            if not (ROOT / page).is_file():
                problems.append(f"{path.relative_to(ROOT)}: {page} does not exist")
        for section in re.findall(r"README(?:\.md)?[ (]+['\"“]([^'\"”]+)['\"”]", text):
            if " ".join(section.split()) not in headings:
                problems.append(f"{path.relative_to(ROOT)}: README has no section {section!r}")
    assert not problems, "\n".join(problems)


def test_every_option_named_in_the_prose_exists():
    """Inline commands (`rtsar process REC.h5 --correct pga`) are not run, but each option
    they name must be one of that command's options: a renamed option fails here."""
    parser = build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    options = {name: set(p._option_string_actions) for name, p in sub.choices.items()}
    unknown, checked = [], 0
    for page in pages():
        text = page.read_text(encoding="utf-8").replace("\n", " ")
        for span in re.findall(r"`(rtsar [^`]+)`", text):
            words = span.split()
            if len(words) < 2 or words[1] not in options:
                continue
            for word in words[2:]:
                m = re.match(r"\[?(--?[a-zA-Z][\w-]*)", word)
                if m:
                    checked += 1
                    if m.group(1) not in options[words[1]]:
                        unknown.append(f"{page_name(page)}: `{span}`: {m.group(1)}")
    assert checked > 100 and not unknown, "\n".join(unknown)


def test_small_runs_append_to_the_commands_named_and_only_those():
    config = {"small": [[["rtsar", "run"], ["--duration", "1"]]], "python": "/py"}
    config["small"].append([["python", "tools/sim_cost.py"], ["--pulses", "400"]])
    run = docs_shim.rewrite("rtsar", ["run", "-o", "demo.h5"], config)
    assert run[-4:] == ["-o", "demo.h5", "--duration", "1"]
    assert docs_shim.rewrite("rtsar", ["quicklook", "a.h5"], config)[-2:] == ["quicklook", "a.h5"]
    tool = docs_shim.rewrite("python", ["tools/sim_cost.py", "--scene", "demo"], config)
    assert tool == ["/py", "tools/sim_cost.py", "--scene", "demo", "--pulses", "400"]
    assert docs_shim.rewrite("python", ["tools/other.py"], config) == ["/py", "tools/other.py"]


def test_the_default_endpoint_becomes_the_pages_own_port():
    mine = "tcp://127.0.0.1:41234"
    assert docs_shim.with_endpoint(["run", "-o", "a.h5"], mine)[-2:] == ["--endpoint", mine]
    given = ["replay", "r.h5", "--endpoint", "tcp://127.0.0.1:9"]
    assert docs_shim.with_endpoint(given, mine) == given
    assert docs_shim.with_endpoint(["subscribe", "-o", "l.h5"], mine) == [
        "subscribe",
        mine,
        "-o",
        "l.h5",
    ]
    assert docs_shim.with_endpoint(["view", "tcp://h:1", "--png", "v.png"], mine)[1] == "tcp://h:1"
    live = docs_shim.with_endpoint(["spotlight", "--live", "--publish", "-o", "x.h5"], mine)
    assert f"--publish={mine}" in live and "--publish" not in live
    assert docs_shim.with_endpoint(["simulate", "s.toml"], mine) == ["simulate", "s.toml"]


def test_a_pages_ports_are_replaced_alike_in_every_block(tmp_path):
    run = PageRun(README, tmp_path / "page")
    a = run.remap_ports("python tools/fake_instrument.py --listen 127.0.0.1:7000 &")
    b = run.remap_ports("rtsar run --serial socket://127.0.0.1:7000 --zmq-in tcp://127.0.0.1:5600")
    port = a.split("127.0.0.1:")[1].split()[0]
    assert port != "7000" and f"socket://127.0.0.1:{port} " in b and "5600" not in b
