"""The benchmarks' shared timing of the viewport's redraw for several states of one view."""

from __future__ import annotations

import time


def alternating_redraws(clouds, states: dict, view, resolution: int, rounds: int) -> dict[str, list[float]]:
    """Milliseconds of each temporal redraw (finished on the GPU) for each named state: every state drawn
    once first (compiles and allocates), then `rounds` rounds of 16 redraws from a restart, the states
    alternating within each round so a load that comes and goes weighs on all alike."""
    from nubis_addon.render import temporal

    tv = temporal.TemporalViewport()
    times: dict[str, list[float]] = {name: [] for name in states}
    try:
        for state in states.values():
            clouds.update(state)
            tv.redraw(clouds, state, view, resolution, 64)
        for _ in range(rounds):
            for name, state in states.items():
                clouds.update(state)
                tv.restart()
                for _ in range(temporal.REDRAWS_PER_SAMPLE):
                    t = time.perf_counter()
                    tv.redraw(clouds, state, view, resolution, 64)
                    tv.sync()
                    times[name].append((time.perf_counter() - t) * 1000.0)
    finally:
        tv.free()
    return times
