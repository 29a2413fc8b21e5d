"""``rtsar bench``'s recording row says where a paced rate under the stream's went (issue 37:
"124 MB/s written, paced at 144 MB/s" with every shot kept, unexplained)."""

from rtsar.app.bench_record import recording_lines


def test_the_paced_row_separates_the_stream_from_the_close():
    row = {
        "folder": "/data",
        "paced": {
            "stream_mb_per_s": 144.0,
            "pulses": 30_016,
            "record_written": 30_016,
            "record_dropped": 0,
            "stream_seconds": 3.0,
            "close_seconds": 0.5,
            "written_mb_per_s": 123.5,
            "seconds_with_close": 3.5,
        },
        "as_fast": {"page_cache_mb_per_s": 500.0, "disk_mb_per_s": 400.0, "mb": 2000.0},
    }
    text = "\n".join(recording_lines("psaltis-max", row))
    assert "30,016 of 30,016 shots recorded, record_dropped 0" in text
    assert "for 3.0 s" in text and "closed 0.50 s after the last shot" in text
    assert "124 MB/s from the first shot to the close" in text
