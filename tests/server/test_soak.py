"""The CI version of benchmarks/soak.py: 4 motes x 60 fps into the full live server for 90 s.

Asserted: the stream goes on (>= 90 % of the frames out and of those not skipped for being
late solved, no queue overflow, nothing malformed),
resident memory grows <= 5 %, and no stall longer than 100 ms while the machine is not overloaded
(load average below its core count). Latency p50/p99 is printed, not asserted: it is a timing goal,
and timing goals live in the benchmark (``python benchmarks/soak.py``, recorded in
docs/BENCHMARKS.md), where the 15 ms p99 target is checked on a known machine. On the slow CI
machines of 2026-11-28 the same code gave p99 27-40 ms with p50 11 ms (2.4x the idle machine's).
"""

from __future__ import annotations

import importlib.util
from pathlib import Path

from .conftest import overloaded

SOAK = Path(__file__).resolve().parents[2] / "benchmarks" / "soak.py"


def test_soak_90_s_memory_stream_stalls():
    spec = importlib.util.spec_from_file_location("soak_bench", SOAK)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    r = mod.run_soak(90.0)
    print(r)
    assert r["ready"]
    assert r["frames"] >= 0.9 * r["expected"], r
    # a frame whose solve the server skipped (it fell behind: a loaded machine) is counted so
    assert r["solved"] >= 0.9 * (r["frames"] - r["solve_skipped"]), r
    assert r["drops"]["queue_overflow"] == 0 and r["drops"]["malformed"] == 0
    assert r["growth_pct"] <= 5.0, r
    if not overloaded():
        assert r["max_gap_ms"] <= 100.0, r
