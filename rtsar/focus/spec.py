"""How corrections are named and asked for: their order, ``--correct NAME[:KEY=VALUE,...]``.

Kept apart from the stages (rtsar.focus.chain builds them) so the command line can offer and
parse corrections without loading any.
"""

from __future__ import annotations

ORDER = ("hcn", "linearize", "reference_region", "pra", "pga")


def parse_spec(text: str) -> tuple[str, dict]:
    """``"name"`` or ``"name:key=value,key=value"`` (numbers as floats) → (name, params)."""
    name, _, rest = text.partition(":")
    name = name.strip().replace("-", "_")
    if name == "hcn+linearize":
        raise ValueError(
            "hcn+linearize is the stage that --correct hcn --correct linearize make together: "
            "give those two (hcn's keys as hcn:KEY=VALUE, the resampling's as linearize:…)"
        )
    if name not in ORDER:
        raise ValueError(f"unknown correction {name!r}; choose from {', '.join(ORDER)}")
    params = {}
    for item in filter(None, (s.strip() for s in rest.split(","))):
        key, eq, value = item.partition("=")
        if not eq:
            raise ValueError(f"correction {name}: expected key=value, got {item!r}")
        try:
            params[key.strip()] = float(value)
        except ValueError:
            params[key.strip()] = value.strip()
    return name, params


def correct_option(stage_name: str) -> str:
    """How a user asks for a stage: ``--correct NAME`` (the stage ``hcn+linearize`` is asked
    for as ``--correct hcn --correct linearize``)."""
    return " ".join(f"--correct {n}" for n in stage_name.split("+"))
