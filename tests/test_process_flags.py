"""`process` and `replay -o` flag the same lines for the same shots (files.md: the same
flagged_line_runs).  From a fault review: shots holding NaN/Inf, in a recording whose
pulse_flags do not mark them, were zeroed by both, but only replay flagged the lines their
aperture touches (1,545 lines against none)."""

import json

import h5py
import numpy as np

from rtsar.app.cli import main
from rtsar.sinks.image_file import read_image

SCENE = """
preset = "tiny"
seed = 2
[[targets]]
along_track_m = 40.0
slant_range_m = 2000.0
"""


def test_nan_shots_flag_the_same_lines_in_process_and_replay(tmp_path, capsys):
    (tmp_path / "s.toml").write_text(SCENE)
    rec = tmp_path / "rec.h5"
    assert main(["simulate", str(tmp_path / "s.toml"), "-o", str(rec), "--pulses", "400"]) == 0
    with h5py.File(rec, "r+") as f:
        shots = f["shots"]
        for p in (100, 101, 300):
            row = shots[p]
            row[5] = np.nan if p != 300 else np.inf
            shots[p] = row
    images = {}
    for name, command in (
        ("process", ["process", str(rec), "-o", str(tmp_path / "p.h5"), "--lens", "numpy"]),
        ("replay", ["replay", str(rec), "--rate", "max", "-o", str(tmp_path / "r.h5")]),
    ):
        extra = ["--lens", "numpy", "--endpoint", f"ipc://{tmp_path}/e"] * (name == "replay")
        assert main(command + extra) == 0
        images[name] = read_image(tmp_path / f"{name[0]}.h5")
    capsys.readouterr()
    (p_img, p_az, _, p_attrs), (r_img, r_az, _, r_attrs) = images["process"], images["replay"]
    n = 64  # the tiny preset's aperture: the lines whose N pulses hold 100, 101 or 300
    want = [[100 - n + 1, n + 1], [300 - n + 1, n]]
    assert json.loads(p_attrs["flagged_line_runs"]) == want
    assert json.loads(r_attrs["flagged_line_runs"]) == want
    assert p_attrs["flagged_lines"] == 2 * n + 1 == json.loads(r_attrs["counters"])["flagged_lines"]
    assert p_attrs["nonfinite_pulses"] == 3 == r_attrs["nonfinite_pulses"]
    # and the same pixels (other correlators, float32 sums: to 1e-4 of the peak)
    np.testing.assert_array_equal(p_az, r_az)
    assert np.abs(p_img - r_img).max() <= 1e-4 * np.abs(p_img).max()
