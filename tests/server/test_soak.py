"""The CI version of benchmarks/soak.py: 4 motes x 60 fps into the full live server for 90 s.

Memory growth and the stream going on are asserted always. Latency p99 and stalls depend on
what else the machine runs: they are asserted against the targets when the machine is not
overloaded (load average below its core count), and printed either way.
"""

from __future__ import annotations

import importlib.util
import os
from pathlib import Path

SOAK = Path(__file__).resolve().parents[2] / "benchmarks" / "soak.py"


def test_soak_90_s_memory_latency_stalls():
    spec = importlib.util.spec_from_file_location("soak_bench", SOAK)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    r = mod.run_soak(90.0)
    print(r)
    assert r["ready"]
    assert r["frames"] >= 0.9 * r["expected"], r
    assert r["drops"]["queue_overflow"] == 0 and r["drops"]["malformed"] == 0
    assert r["growth_pct"] <= 5.0, r
    if os.getloadavg()[0] < (os.cpu_count() or 1):
        assert r["p99_ms"] <= 15.0, r
        assert r["max_gap_ms"] <= 100.0, r
