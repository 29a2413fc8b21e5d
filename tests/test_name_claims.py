"""Every writer honours a live writer's claim on its file name (issue 29): a name another
rtsar process is writing now is refused in one line, exit status 2, before any work."""

import errno
import os
import subprocess
import sys

import pytest

from rtsar.app.cli import main
from rtsar.sinks import name_claim

SCENE = """
preset = "tiny"
pulses = 200
[[targets]]
along_track_m = 0.0
slant_range_m = 2000.0
"""

HOLDER = """
import sys
from rtsar.sinks.name_claim import NameClaim
claims = [NameClaim(p) for p in sys.argv[1:]]
print("held", flush=True)
sys.stdin.read()
"""


@pytest.fixture
def held(tmp_path):
    """Names held by another process, as a live `run -o`/`subscribe -o` holds its own."""
    names = {k: tmp_path / f"{k}.h5" for k in ("img", "rec", "raw")}
    names["cphd"] = tmp_path / "x.cphd"
    names["sig"] = tmp_path / "s"
    files = [*names.values()]
    files += [tmp_path / "s.sigmf-meta", tmp_path / "s.sigmf-data", tmp_path / "out" / "r-img.h5"]
    (tmp_path / "out").mkdir()
    for path in files:
        path.write_bytes(b"the live file")
    proc = subprocess.Popen(
        [sys.executable, "-c", HOLDER, *map(str, files)],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        text=True,
    )
    assert proc.stdout.readline().strip() == "held"
    yield names, files
    proc.stdin.close()
    proc.wait(10)


def test_every_writer_refuses_a_name_being_written_live(tmp_path, held, capsys):
    """Before, `process REC -o X.h5` while `run -o X.h5` ran replaced X.h5 (the run's 7,489
    lines lost, and the run said they were saved): simulate, process and export ignored the
    claims of the live writers."""
    names, files = held
    scene = tmp_path / "s.toml"
    scene.write_text(SCENE)
    rec = tmp_path / "free.h5"
    assert main(["simulate", str(scene), "-o", str(rec)]) == 0
    capsys.readouterr()
    ep = ["--endpoint", "ipc://" + str(tmp_path / "ep"), "--lens", "numpy"]
    commands = [
        ["simulate", str(scene), "-o", str(names["rec"])],
        ["process", str(rec), "-o", str(names["img"]), "--lens", "numpy"],
        ["export", str(rec), "--cphd", str(names["cphd"])],
        ["export", str(rec), "--sigmf", str(names["sig"])],
        ["subscribe", "ipc://" + str(tmp_path / "none"), "-o", str(names["img"])],
        ["run", "--scene", str(scene), "-o", str(names["img"]), *ep],
        ["run", "--scene", str(scene), "--record", str(names["raw"]), *ep],
        ["replay", str(rec), "--rate", "max", "-o", str(names["img"]), *ep],
    ]
    for argv in commands:
        assert main(argv) == 2, argv
        out, err = capsys.readouterr()
        lines = err.strip().splitlines()
        assert len(lines) == 1 and "another rtsar process (pid" in lines[0], (argv, err)
        assert "is writing it now" in lines[0] and "preparing" not in out, argv
    for path in files:  # untouched, and no temporary of ours beside them
        assert path.read_bytes() == b"the live file"
    hidden = [p.name for p in tmp_path.rglob(".*") if not p.name.endswith("-writing")]
    assert hidden == []


def test_batch_refuses_an_output_being_written_live(tmp_path, held, capsys):
    names, files = held
    folder = tmp_path / "recs"
    folder.mkdir()
    scene = tmp_path / "s.toml"
    scene.write_text(SCENE)
    assert main(["simulate", str(scene), "-o", str(folder / "r.h5")]) == 0
    capsys.readouterr()
    argv = ["batch", str(folder), "--out-dir", str(tmp_path / "out"), "--lens", "numpy"]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "r-img.h5: another rtsar process (pid" in err[0]
    assert (tmp_path / "out" / "r-img.h5").read_bytes() == b"the live file"


def test_an_output_being_written_is_claimed_for_the_whole_write(tmp_path):
    """The other way round: while `process`/`simulate` writes a name (under a temporary name
    until it is complete), a live writer of that name is refused, so neither replaces the
    other's file."""
    from rtsar.sinks.io import replace_when_complete

    path = tmp_path / "img.h5"
    probe = (
        "import sys\nfrom rtsar.sinks.name_claim import NameClaim\n"
        "try:\n    NameClaim(sys.argv[1])\nexcept ValueError as exc:\n    print(exc)\n"
    )
    with replace_when_complete(path) as tmp:
        tmp.write_bytes(b"an image")
        said = subprocess.run(
            [sys.executable, "-c", probe, str(path)], capture_output=True, text=True, timeout=60
        ).stdout
    assert "another rtsar process (pid" in said and "is writing it now" in said
    assert path.read_bytes() == b"an image"
    assert [p.name for p in tmp_path.iterdir()] == ["img.h5"]  # the claim went with the write


FINISHER = """
import sys
from rtsar.sinks.name_claim import NameClaim
claim = NameClaim(sys.argv[1])
claim.finishing()
print("finishing", flush=True)
sys.stdin.read()
"""


def test_a_reader_waits_only_for_a_live_writer_finishing_and_changes_nothing(tmp_path, monkeypatch):
    # (A cold review of the wait for a writer's final attributes, rtsar.sinks.name_claim.)
    path = tmp_path / "img.h5"
    proc = subprocess.Popen(
        [sys.executable, "-c", FINISHER, str(path)],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        text=True,
    )
    try:
        assert proc.stdout.readline().strip() == "finishing"
        (mark,) = tmp_path.glob(".img.h5.partial-*-writing")
        assert name_claim.is_finishing(path)
        waited = name_claim.wait_while_finishing(path, 0.3, poll_s=0.05)
        assert 0.3 <= waited < 5  # a live writer finishing: waited for, up to the bound
        # A reader of another account may only read the mark: it waits all the same.
        real_open = os.open

        def read_only(p, flags, *a):
            if str(p) == str(mark) and flags & (os.O_WRONLY | os.O_RDWR):
                raise PermissionError(13, "Permission denied", str(p))
            return real_open(p, flags, *a)

        monkeypatch.setattr(name_claim.os, "open", read_only)
        assert name_claim.wait_while_finishing(path, 0.2, poll_s=0.05) >= 0.2
        # Where locks do not work, nothing would end a dead writer's mark: not waited for.
        monkeypatch.setattr(name_claim.fcntl, "flock", _no_locks)
        assert name_claim.wait_while_finishing(path, 5.0) < 1.0
        monkeypatch.undo()
    finally:
        proc.communicate("", timeout=30)
    # The writer killed while finishing leaves its mark unlocked: a reader does not wait for
    # it and does not remove it (that is a writer's to do, with write access to the folder).
    mark.write_bytes(name_claim.FINISHING)
    assert name_claim.wait_while_finishing(path, 5.0) < 1.0 and mark.exists()
    # This process's own claim, finishing: never waited for by its own reads.
    mine = name_claim.NameClaim(tmp_path / "own.h5")
    mine.finishing()
    assert name_claim.wait_while_finishing(tmp_path / "own.h5", 5.0) < 1.0
    mine.release()


def _no_locks(fd, op):
    raise OSError(errno.ENOLCK, "No locks available")
