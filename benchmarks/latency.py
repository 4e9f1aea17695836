"""Latency of the live server: capture time -> pose published, over real Zenoh on loopback.

Simulated motes run in a separate process (``python -m samba_server.simmotes``) on the same
machine and clock; the server runs here. Latency is ``publish time - frame time``, where the
frame time is the mean corrected capture time of the frame's packets (it trails the true
capture by the minimum transport latency, about 0.15 ms on loopback). Two configurations:

- ``pipeline``: ingest, sync, labelling (3D points named as markers), publish (no skeleton solve);
- ``full``: the same plus ``Reconstructor.solve`` on every frame the server keeps up with
  (``max_lag_ms`` from configs/server.toml skips the solve of frames that are already late).

Also searched: the highest mote frame rate (4 motes) the pipeline sustains without falling
behind (>= 95 % of frames out, median latency not growing and at most 15 ms: a pipeline that
keeps a standing backlog of a third of a second keeps up in count but not in time). Records into docs/BENCHMARKS.md
(its two sections replaced on rerun).

TLS cost: the same 4 x 60 runs over plain TCP and over mutual TLS with access control
(``--tls``, keys from ``samba-keys``), interleaved plain/TLS/plain/TLS, side by side in their own
section ("Server latency: TLS cost"). Target: TLS adds <= 0.5 ms p50.
Usage: ``python benchmarks/latency.py [--seconds 5] [--no-write] [--tls-only]``.
"""

from __future__ import annotations

import argparse
import os
import platform
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from samba_common.calib import default_rig
from samba_server.live import LiveServer
from samba_server.server import Server, ServerConfig
from samba_server.app import load_server_configs, make_reconstructor
from samba_server.sync import SyncConfig

ROOT = Path(__file__).resolve().parents[1]
_KEEPS_UP_P50_MS = 15.0  # a rate counts as sustained only with the median latency at most this


def _endpoint(proto: str = "tcp") -> str:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return f"{proto}/127.0.0.1:{s.getsockname()[1]}"


def run(n_motes: int, fps: float, seconds: float, solve: bool, tls: str | None = None) -> dict:
    """One run; ``tls``: keys folder for mutual TLS + access control (None = plain TCP)."""
    from samba_common import keys

    cfg = load_server_configs()
    ep = _endpoint("tls" if tls else "tcp")
    server = Server(default_rig(n_motes), reconstructor=make_reconstructor(None) if solve else None,
                    config=ServerConfig(keep_history=False, max_lag_ms=cfg.server.max_lag_ms),
                    sync_config=SyncConfig(**{**cfg.sync.__dict__, "fps": fps}), tri_config=cfg.triangulate,
                    label_config=cfg.labelling)
    extra = keys.server_settings(tls, "bench") if tls else None
    with LiveServer(server, session="bench", listen=[ep], extra=extra):
        proc = subprocess.Popen([sys.executable, "-m", "samba_server.simmotes", "--connect", ep, "--motes",
                                 str(n_motes), "--fps", str(fps), "--duration", str(seconds)]
                                + (["--tls", str(tls)] if tls else []),
                                stdout=subprocess.PIPE, text=True)
        ready = proc.stdout.readline().strip()
        out = proc.communicate(timeout=seconds + 30)[0]
        time.sleep(0.3)
    lat = np.array(server.stats.latency_ms)
    lat = lat[len(lat) // 10:]  # drop the start-up (clock filter warm-up, body estimate)
    half = len(lat) // 2
    expected = seconds * fps
    return {"motes": n_motes, "fps": fps, "solve": solve, "tls": bool(tls), "ready": ready == "ready",
            "sent": out.strip(), "frames": server.stats.frames, "expected": int(expected),
            "solved": server.stats.solved, "skipped": server.stats.solve_skipped,
            "p50": float(np.percentile(lat, 50)) if len(lat) else float("nan"),
            "p99": float(np.percentile(lat, 99)) if len(lat) else float("nan"),
            "growing": bool(half > 10 and np.median(lat[half:]) > 2 * np.median(lat[:half]) + 5),
            "late": sum(m.late for m in server.sync.motes.values())}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seconds", type=float, default=5.0)
    ap.add_argument("--no-write", action="store_true")
    ap.add_argument("--tls-only", action="store_true", help="only the plain vs TLS comparison")
    args = ap.parse_args()
    tls_cost(args.seconds, not args.no_write)
    if args.tls_only:
        return 0
    rows = []
    for solve in (False, True):
        for n in (2, 4):
            r = run(n, 60.0, args.seconds, solve)
            rows.append(r)
            print(r, flush=True)
    best = None
    for fps in (60, 120, 180, 240, 360):
        r = run(4, float(fps), args.seconds, False)
        print(r, flush=True)
        if (r["frames"] >= 0.95 * r["expected"] and not r["growing"] and r["p50"] <= _KEEPS_UP_P50_MS
                and r["late"] <= 0.01 * 4 * r["expected"]):
            best = fps
        else:
            break
    lines = [f"Machine: {platform.platform()}, {platform.processor() or platform.machine()}, {os.cpu_count()} CPUs, "
             f"Python {platform.python_version()}. Motes simulated in a separate process, Zenoh over loopback, "
             f"{args.seconds:.0f} s per run. Latency = pose publish - frame capture time (server clock).", "",
             "| motes x fps | solve | frames out / expected | solved (skipped) | p50 ms | p99 ms | late pkts |",
             "|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['motes']} x {r['fps']:.0f} | {'yes' if r['solve'] else 'no'} | {r['frames']} / "
                     f"{r['expected']} | {r['solved']} ({r['skipped']}) | {r['p50']:.2f} | {r['p99']:.2f} | {r['late']} |")
    lines += ["", f"Highest rate sustained by the pipeline without the solve at 4 motes: {best} fps "
              "(tried 60, 120, 180, 240, 360).", "Targets: p50 <= 5 ms, p99 <= 15 ms at 4 x 60."]
    print("\n".join(lines))
    if not args.no_write:
        from _record import record

        record("Server latency (benchmarks/latency.py)", lines)
    return 0


def tls_cost(seconds: float, write: bool) -> None:
    """4 x 60 over plain TCP and mutual TLS, interleaved, with and without the solve."""
    import tempfile

    from samba_common import keys

    from _record import record

    with tempfile.TemporaryDirectory(prefix="samba-bench-keys-") as tmp:
        keys.init_keys(tmp, motes=[f"cam{i}" for i in range(4)])
        runs = []
        for solve in (False, True):
            for _rep in range(2):
                for tls in (None, tmp):
                    r = run(4, 60.0, seconds, solve, tls)
                    runs.append(r)
                    print(r, flush=True)
    lines = [f"4 motes x 60 fps, motes in a separate process, {seconds:.0f} s per run, runs interleaved "
             "plain / TLS / plain / TLS. TLS = mutual TLS (ECDSA P-256 certificates from samba-keys) plus the "
             "server's access control, as `--tls` runs it.", "",
             "| solve | transport | frames out / expected | p50 ms | p99 ms |", "|---|---|---|---|---|"]
    summary = {}
    for r in runs:
        lines.append(f"| {'yes' if r['solve'] else 'no'} | {'TLS' if r['tls'] else 'TCP'} | {r['frames']} / "
                     f"{r['expected']} | {r['p50']:.2f} | {r['p99']:.2f} |")
        summary.setdefault((r["solve"], r["tls"]), []).append((r["p50"], r["p99"]))
    lines.append("")
    for solve in (False, True):
        plain, tls = np.array(summary[(solve, False)]), np.array(summary[(solve, True)])
        d50, d99 = tls[:, 0].mean() - plain[:, 0].mean(), tls[:, 1].mean() - plain[:, 1].mean()
        lines.append(f"- {'with' if solve else 'without'} the solve: TLS adds {d50:+.2f} ms p50, {d99:+.2f} ms p99 "
                     f"(means of the runs; target <= +0.5 ms p50).")
    text = "\n".join(lines)
    print(text)
    if write:
        record("Server latency: TLS cost (benchmarks/latency.py)", lines)


if __name__ == "__main__":
    sys.exit(main())
