"""``rtsar bench``: a line's latency against the offered rate, each rate run with the
granularity a live run at that rate chooses (rtsar.app.live_granularity; issue 38).

The shots are offered paced, as an instrument sends them (a full first queue drops them), at
25, 50, 100 and 150 % of the preset's PRF, those the pipeline's measured capacity allows.  The
goal each row is read against: median ≤ 1 ms + one pulse period at that rate, p99 ≤ 3 × the
median, nothing dropped.  ``plot_latency`` draws the rows of every preset (``--plot``).
"""

from __future__ import annotations

from ..stream.granularity import live_correlator
from ..stream.settings import PipelineSettings
from .live_granularity import GranularityRequest

OFFERED = (0.25, 0.5, 1.0, 1.5)  # fractions of the PRF


def goal_median_ms(rate_hz: float) -> float:
    """The goal's median at a rate: 1 ms + one pulse period."""
    return 1.0 + 1e3 / rate_hz


def goal_parts(row: dict) -> dict[str, bool]:
    """Each part of the goal, met or not: median ≤ 1 ms + a pulse period, p99 ≤ 3 × median,
    no shot dropped."""
    median, p99 = row["latency_median_ms"], row["latency_p99_ms"]
    return {
        "median": median <= goal_median_ms(row["offered_hz"]),
        "p99": p99 <= 3 * median,
        "dropped": not row["dropped"],
    }


def meets_goal(row: dict) -> bool:
    """Every part of the goal met (goal_parts)."""
    return all(goal_parts(row).values())


def goal_words(row: dict) -> str:
    """The goal's parts with their verdicts, each on its own: a row whose median is met and
    whose p99 is not says so, e.g. 'median <= 2.25 ms met, p99 <= 3x the median (1.68 ms)
    not met, 0 dropped met'."""
    met = goal_parts(row)
    said = {True: "met", False: "not met"}
    return (
        f"median <= {goal_median_ms(row['offered_hz']):.2f} ms {said[met['median']]}, "
        f"p99 <= 3x the median ({3 * row['latency_median_ms']:.2f} ms) {said[met['p99']]}, "
        f"0 dropped {said[met['dropped']]}"
    )


def latency_against_rate(cfg, shots, seconds: float, capacity: float, log, stream_run) -> list:
    """One paced run a rate of OFFERED up to ``capacity`` (× real time, measured at max rate),
    each ``seconds`` of source time; rows with the granularity chosen and the latencies."""
    prf = cfg.geometry.prf_hz
    rows = []
    live = live_correlator(cfg)[0].processor.correlator  # the one each row's request runs
    log(
        f"  latency against the offered rate ({live}, the correlator and the granularity a "
        "live run chooses at each rate; goal: median <= 1 ms + a pulse period, p99 <= 3x "
        "the median, 0 dropped)"
    )
    for fraction in OFFERED:
        if fraction > capacity:
            log(f"    {fraction:4.0%} of the PRF: over the capacity measured ({capacity:.2f}x)")
            continue
        rate_hz = prf * fraction
        chosen_cfg, settings, g, words = GranularityRequest(rate_hz).apply(cfg, PipelineSettings())
        r = stream_run(chosen_cfg, shots, seconds, fraction, settings)
        grew = r.get("correlator_growths")  # the block grown while behind (rtsar.stream.growth)
        row = {
            "correlator": chosen_cfg.processor.correlator,
            "offered_fraction": fraction,
            "offered_hz": rate_hz,
            "block_lines": g.block_lines,
            "grown_to_lines": r.get("correlator_block_lines") if grew else None,
            "strip_lines": settings.strip_lines,
            "granularity": words,
            "kept_fraction": r["kept_fraction"],
            "dropped": r["dropped_pulses"],
            "latency_median_ms": r["latency_median_ms"],
            "latency_p99_ms": r["latency_p99_ms"],
        }
        row["goal_parts"] = goal_parts(row)  # which part a miss is (goal_words says it)
        row["meets_goal"] = meets_goal(row)
        rows.append(row)
        to = row["grown_to_lines"]
        log(
            f"    {fraction:4.0%} of the PRF ({rate_hz:,.0f} Hz): blocks of {row['block_lines']}"
            + (f" grown to {to} (it fell behind)" if to else "")
            + f", strips of {row['strip_lines']}; kept {100 * r['kept_fraction']:.1f} %, dropped "
            f"{r['dropped_pulses']:,}; latency median {row['latency_median_ms']:.2f} ms, p99 "
            f"{row['latency_p99_ms']:.2f} ms (goal: {goal_words(row)})"
        )
    return rows


def plot_latency(results: list[dict], path: str) -> None:
    """Median and p99 latency against the offered rate (% of the PRF), a line pair a preset,
    with the goal's median; ``results``: bench_pipeline's, each with its
    ``latency_against_rate`` rows."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.4, 4.2))
    for k, result in enumerate(results):
        rows = result.get("latency_against_rate") or []
        if not rows:
            continue
        x = [100 * r["offered_fraction"] for r in rows]
        color = f"C{k}"
        name = result["preset"]
        ax.plot(x, [r["latency_median_ms"] for r in rows], "o-", color=color, label=f"{name}")
        ax.plot(x, [r["latency_p99_ms"] for r in rows], "s--", color=color, label=f"{name} p99")
        goal = [goal_median_ms(r["offered_hz"]) for r in rows]
        ax.plot(x, goal, ":", color=color, label=f"{name} goal (median)")
    ax.set_yscale("log")
    ax.set_xlabel("offered rate, % of the PRF")
    ax.set_ylabel("line latency, ms (last pulse → strip published)")
    ax.legend(fontsize="small")
    ax.grid(True, which="both", alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
