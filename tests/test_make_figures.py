"""tools/make_figures.py writes to an output folder, never over the repository's own figures
unless asked (issue 31: run as the README said, it rewrote figures tracked by git)."""

import subprocess
import sys

from tools_loader import TOOLS, load_tool

ROOT = TOOLS.parent


def test_by_default_the_figures_go_to_a_folder_of_the_current_directory(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    out = load_tool("make_figures").parse_args([]).out_dir
    assert out.resolve() == tmp_path / "figures"
    assert ROOT not in out.resolve().parents


def test_an_out_dir_is_taken_as_given(tmp_path):
    assert load_tool("make_figures").parse_args(["--out-dir", str(tmp_path)]).out_dir == tmp_path


def test_refresh_writes_over_the_figures_the_docs_show():
    make_figures = load_tool("make_figures")
    out = make_figures.parse_args(["--refresh"]).out_dir
    assert out == ROOT / "docs" / "pages" / "figures"
    docs = (ROOT / "README.md").read_text(encoding="utf-8") + "".join(
        p.read_text(encoding="utf-8") for p in (ROOT / "docs" / "pages").rglob("*.md")
    )
    for name in make_figures.FIGURE_NAMES:
        assert (out / name).is_file() and f"figures/{name}" in docs


def test_refresh_and_an_out_dir_do_not_go_together(tmp_path):
    done = subprocess.run(
        [sys.executable, str(TOOLS / "make_figures.py"), "--refresh", "--out-dir", str(tmp_path)],
        capture_output=True,
        text=True,
    )
    assert done.returncode == 2 and "not allowed with" in done.stderr


def test_the_help_says_where_it_writes():
    done = subprocess.run(
        [sys.executable, str(TOOLS / "make_figures.py"), "--help"], capture_output=True, text=True
    )
    assert done.returncode == 0 and "--refresh" in done.stdout and "./figures" in done.stdout
