"""NGA's SICD consistency checks (sarkit's SicdConsistency) on a written file, for the export
tests: the checks that failed at severity Error."""

from __future__ import annotations


def sarkit_errors(path) -> tuple[bool, list]:
    """(sarkit says the file passes, [(check, details) of each failed Error]) of the SICD at
    ``path``."""
    import sarkit.verification as skver

    with open(path, "rb") as f:
        con = skver.SicdConsistency.from_file(f)
        con.check()
    errors = [
        (name, d["details"])
        for name, v in con.failures().items()
        for d in v["details"]
        if not d["passed"] and d["severity"] == "Error"
    ]
    return con.passes(), errors
