"""tools/mutation_probe.py and its list, tools/mutants.toml (issue 39): the list stays runnable
(each mutant's ``before`` once in its file, its tests there, the names unique), and the probe
applies one mutant exactly and restores the file.  Running the mutants is the tool's work, not
the suite's (minutes): ``python tools/mutation_probe.py``."""

import subprocess
from pathlib import Path

import pytest
from tools_loader import load_tool

ROOT = Path(__file__).resolve().parents[1]
probe = load_tool("mutation_probe")


def test_every_mutant_of_the_list_still_applies_once_and_names_real_tests():
    mutants = probe.load_mutants(probe.DEFAULT_LIST)
    assert len(mutants) >= 30
    stale = []
    for m in mutants:
        found = (ROOT / m["file"]).read_text(encoding="utf-8").count(m["before"])
        if found != 1 or m["before"] == m["after"]:
            stale.append(f"{m['name']}: 'before' found {found} times in {m['file']}")
        stale += [f"{m['name']}: no {t}" for t in m["tests"] if not (ROOT / t).exists()]
    assert not stale, "tools/mutants.toml needs updating for the code:\n" + "\n".join(stale)


def test_a_mutant_is_applied_exactly_and_restored(tmp_path):
    tree = tmp_path / "tree"
    (tree / "pkg").mkdir(parents=True)
    (tree / "pkg" / "m.py").write_text("x = 1\ny = x + 1\n")
    subprocess.run(["git", "init", "-q", str(tree)], check=True)
    subprocess.run(["git", "-C", str(tree), "add", "."], check=True)
    subprocess.run(
        ["git", "-C", str(tree), "-c", "user.name=t", "-c", "user.email=t@t", "commit", "-qm", "t"],
        check=True,
    )
    mutant = {"name": "m", "file": "pkg/m.py", "before": "x + 1", "after": "x - 1"}
    assert probe.apply(tree, mutant) is None
    assert (tree / "pkg" / "m.py").read_text() == "x = 1\ny = x - 1\n"
    probe.restore(tree, "pkg/m.py")
    assert (tree / "pkg" / "m.py").read_text() == "x = 1\ny = x + 1\n"
    assert "occurs 0 times" in probe.apply(tree, dict(mutant, before="z"))
    assert "occurs 2 times" in probe.apply(tree, dict(mutant, before="x"))


def test_the_table_counts_what_was_caught():
    rows = [
        {"name": "a", "file": "f.py", "verdict": "caught", "detail": "t::x", "seconds": 3.0},
        {"name": "b", "file": "g.py", "verdict": "survived", "detail": "", "seconds": 9.0},
    ]
    text = probe.table(rows)
    assert "| a | `f.py` | caught | t::x | 3 |" in text
    assert "| b | `g.py` | survived | — | 9 |" in text
    assert text.endswith("1 of 2 caught")


def test_an_unknown_mutant_name_is_one_line(capsys):
    with pytest.raises(SystemExit) as exc:
        probe.main(["--only", "no-such-mutant"])
    assert exc.value.code == 2
    assert "no mutant named no-such-mutant" in capsys.readouterr().err
