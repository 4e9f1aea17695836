"""One-page PNG summary of a recorded take (``samba-inspect --plot out.png``).

Panels: marker visibility per mote (fraction of frames in which each labelled marker was
measured, over time), marker heights and the top-down paths of the hips/wrists/ankles from the
solved poses, and latency over time (pose capture -> publish, and per-mote packet capture ->
arrival at the server). Data comes from the server's recording reader
(:func:`samba_server.record.iter_messages`).

matplotlib runs with the Agg backend (no display needed); it is imported only here.
"""

from __future__ import annotations

import logging
import os
from dataclasses import dataclass, field

import numpy as np

from samba_common.skeleton import J, MARKER_JOINT, MARKER_NAMES

log = logging.getLogger(__name__)

VIS_BIN_S = 0.25  #: width of the time bins of the visibility panel, seconds


@dataclass
class MoteTrack:
    """One mote's packets: t (P,) s capture time from take start; seen (P, 8) bool (marker
    measured in that packet); latency_ms (P,) arrival - capture (NaN if unknown)."""

    t: np.ndarray
    seen: np.ndarray
    latency_ms: np.ndarray


@dataclass
class TakeData:
    """What the plots need from a take.

    pose_t (F,) s from take start; joints (F, 13, 3) m; markers (F, 8, 3) m (NaN missing);
    pose_latency_ms (F,); motes: id -> MoteTrack; bad: undecodable messages skipped.
    """

    pose_t: np.ndarray
    joints: np.ndarray
    markers: np.ndarray
    pose_latency_ms: np.ndarray
    motes: dict[str, MoteTrack] = field(default_factory=dict)
    bad: int = 0
    truncated: bool = False


def read_take_data(path: str | os.PathLike) -> TakeData:
    """Read a take.mcap through :mod:`samba_server.record`; bad messages are skipped and counted."""
    from samba_common.pose_wire import PoseError, decode_pose
    from samba_common.wire import FLAG_LOST, FLAG_PREDICTED, PacketError, decode_packet
    from samba_server import record

    reader = record.TakeReader(path)
    poses: list[tuple[int, np.ndarray, np.ndarray, float]] = []
    packets: dict[str, list[tuple[int, np.ndarray, float]]] = {}
    bad = 0
    for msg in reader:
        if msg.topic == record.POSE_TOPIC:
            try:
                p = decode_pose(msg.data)
            except PoseError:
                bad += 1
                continue
            m = p.markers if p.markers is not None else np.full((8, 3), np.nan)
            poses.append((p.t_ns, np.asarray(p.joints, float), np.asarray(m, float), float(p.latency_ms)))
        elif msg.mote_id is not None:
            try:
                pk = decode_packet(msg.data)
            except PacketError:
                bad += 1
                continue
            seen = np.zeros(len(MARKER_NAMES), bool)
            measured = (pk.flags & (FLAG_PREDICTED | FLAG_LOST)) == 0
            lab = pk.labels[measured & (pk.labels < len(MARKER_NAMES))]
            seen[lab] = True
            lat = (msg.log_time - pk.t_ns) / 1e6 if pk.t_ns > 0 else np.nan
            packets.setdefault(msg.mote_id, []).append((pk.t_ns, seen, lat))
    if bad:
        log.warning("%s: skipped %d undecodable messages", path, bad)
    starts = [p[0] for p in poses[:1]] + [v[0][0] for v in packets.values() if v]
    t0 = min(starts) if starts else 0
    poses.sort(key=lambda p: p[0])
    data = TakeData(
        pose_t=np.array([(p[0] - t0) / 1e9 for p in poses]),
        joints=np.array([p[1] for p in poses]).reshape(-1, 13, 3),
        markers=np.array([p[2] for p in poses]).reshape(-1, 8, 3),
        pose_latency_ms=np.array([p[3] for p in poses]),
        bad=bad, truncated=reader.truncated)
    for mote, rows in sorted(packets.items()):
        rows.sort(key=lambda r: r[0])
        data.motes[mote] = MoteTrack(np.array([(r[0] - t0) / 1e9 for r in rows]),
                                     np.array([r[1] for r in rows]).reshape(-1, 8),
                                     np.array([r[2] for r in rows], dtype=float))
    return data


def _visibility(track: MoteTrack, edges: np.ndarray) -> np.ndarray:
    """(8, B) fraction of the mote's packets in each time bin where each marker was measured
    (NaN for bins with no packet at all)."""
    idx = np.clip(np.searchsorted(edges, track.t, side="right") - 1, 0, len(edges) - 2)
    counts = np.bincount(idx, minlength=len(edges) - 1).astype(float)
    out = np.full((len(MARKER_NAMES), len(edges) - 1), np.nan)
    for k in range(len(MARKER_NAMES)):
        hits = np.bincount(idx, weights=track.seen[:, k].astype(float), minlength=len(edges) - 1)
        out[k] = np.where(counts > 0, hits / np.maximum(counts, 1), np.nan)
    return out


def take_data_from_arrays(joints: np.ndarray, t: np.ndarray, markers: np.ndarray | None = None,
                          latency_ms: np.ndarray | None = None) -> TakeData:
    """TakeData from pose arrays alone (no mote packets): joints (F, 13, 3) m, t (F,) s,
    markers (F, 8, 3) m or None, latency_ms (F,) or None."""
    joints = np.asarray(joints, dtype=np.float64).reshape(-1, 13, 3)
    t = np.asarray(t, dtype=np.float64).reshape(-1)
    if len(t) != len(joints):
        raise ValueError(f"joints has {len(joints)} frames but t has {len(t)}")
    F = len(t)
    m = np.full((F, 8, 3), np.nan) if markers is None else np.asarray(markers, float).reshape(F, 8, 3)
    return TakeData(pose_t=t - (t[0] if F else 0.0), joints=joints, markers=m,
                    pose_latency_ms=np.full(F, np.nan) if latency_ms is None else np.asarray(latency_ms, float))


def plot_take(take, out, *more, title: str | None = None) -> TakeData:
    """Write the summary PNG of a take; returns the data plotted.

    Call forms: ``plot_take("take.mcap", "out.png")`` (all panels, through the recording reader),
    ``plot_take(take_data, "out.png")``, or ``plot_take(joints (F,13,3), t (F,), "out.png")``
    (poses only: no visibility or packet-latency panels). Raises ValueError when there is
    nothing to plot."""
    if isinstance(take, np.ndarray):
        if not more:
            raise ValueError("plot_take(joints, t, out): the output path is missing")
        take, out = take_data_from_arrays(take, out), more[0]
    import matplotlib

    matplotlib.use("Agg", force=True)
    import matplotlib.pyplot as plt

    data = take if isinstance(take, TakeData) else read_take_data(take)
    if len(data.pose_t) == 0 and not data.motes:
        where = "the take" if isinstance(take, TakeData) else str(take)
        raise ValueError(f"{where}: no poses and no mote packets to plot")
    name = title or (os.path.basename(os.fspath(take)) if not isinstance(take, TakeData) else "take")
    t_end = max([data.pose_t[-1] if len(data.pose_t) else 0.0] +
                [m.t[-1] for m in data.motes.values() if len(m.t)]) + 1e-9
    edges = np.arange(0.0, t_end + VIS_BIN_S, VIS_BIN_S)
    n_motes = max(len(data.motes), 1)
    fig = plt.figure(figsize=(13, 4.0 + 1.1 * n_motes), dpi=100, layout="constrained")
    gs = fig.add_gridspec(2 + n_motes, 2, height_ratios=[1.0] * n_motes + [2.2, 2.0])
    fig.suptitle(f"Samba take: {name}" + ("  (truncated)" if data.truncated else ""))
    cmap = matplotlib.colormaps["viridis"].with_extremes(bad="#dddddd")
    axes_vis = []
    for r, (mote, track) in enumerate(data.motes.items()):
        ax = fig.add_subplot(gs[r, :], sharex=axes_vis[0] if axes_vis else None)
        vis = _visibility(track, edges)
        im = ax.imshow(np.ma.masked_invalid(vis), aspect="auto", interpolation="nearest", cmap=cmap,
                       vmin=0, vmax=1, extent=(edges[0], edges[-1], len(MARKER_NAMES) - 0.5, -0.5))
        ax.set_yticks(range(len(MARKER_NAMES)), [n.replace("_", " ") for n in MARKER_NAMES], fontsize=6)
        rate = (len(track.t) - 1) / max(track.t[-1] - track.t[0], 1e-9) if len(track.t) > 1 else 0.0
        ax.set_ylabel(f"{mote}\n{100 * track.seen.mean():.0f}% seen\n{rate:.0f} fps", fontsize=8)
        axes_vis.append(ax)
    if axes_vis:
        axes_vis[0].set_title("marker visibility per mote (fraction of packets measuring each marker; "
                              "grey = no packets)",
                              fontsize=9)
        fig.colorbar(im, ax=axes_vis, shrink=0.8, label="seen")
        axes_vis[-1].set_xlabel("time (s)")
    else:
        ax = fig.add_subplot(gs[0, :])
        ax.text(0.5, 0.5, "no mote packets in this data: marker visibility per mote needs the take.mcap",
                ha="center", va="center", transform=ax.transAxes)
        ax.set_axis_off()
    # trajectories: marker heights over time, top-down paths
    ax_h = fig.add_subplot(gs[n_motes, 0])
    have_markers = bool(np.isfinite(data.markers).any())
    heights = data.markers if have_markers else data.joints[:, list(MARKER_JOINT)]
    for k, mname in enumerate(MARKER_NAMES):
        ax_h.plot(data.pose_t, heights[:, k, 2], lw=0.8, label=mname)
    ax_h.set_title("triangulated marker height" if have_markers else
                   "height of the marker joints (no triangulated markers in this data)", fontsize=9)
    ax_h.set_xlabel("time (s)")
    ax_h.set_ylabel("z (m)")
    ax_h.legend(fontsize=6, ncol=2, loc="upper right")
    ax_xy = fig.add_subplot(gs[n_motes, 1])
    if len(data.pose_t):
        hip = 0.5 * (data.joints[:, J["left_hip"]] + data.joints[:, J["right_hip"]])
        ax_xy.plot(hip[:, 0], hip[:, 1], "k-", lw=1.2, label="hip midpoint")
        for jn, style in (("left_wrist", "b-"), ("right_wrist", "r-"), ("left_ankle", "b:"), ("right_ankle", "r:")):
            ax_xy.plot(data.joints[:, J[jn], 0], data.joints[:, J[jn], 1], style, lw=0.7, label=jn.replace("_", " "))
        solved = np.all(np.isfinite(data.joints), axis=(1, 2))
        ax_xy.set_title(f"top view of the solved joints ({100 * solved.mean():.0f}% of frames solved)", fontsize=9)
    ax_xy.set_aspect("equal", adjustable="datalim")
    ax_xy.set_xlabel("x (m)")
    ax_xy.set_ylabel("y (m)")
    ax_xy.legend(fontsize=6, loc="upper right")
    ax_l = fig.add_subplot(gs[n_motes + 1, :])
    if len(data.pose_t):
        ax_l.plot(data.pose_t, data.pose_latency_ms, "k-", lw=1.0, label="pose: capture -> publish")
    for mote, track in data.motes.items():
        ax_l.plot(track.t, track.latency_ms, lw=0.6, alpha=0.8, label=f"{mote}: capture -> arrival")
    ax_l.set_title("latency over time", fontsize=9)
    ax_l.set_xlabel("time (s)")
    ax_l.set_ylabel("ms")
    ax_l.legend(fontsize=6, ncol=4, loc="upper right")
    tmp = f"{os.fspath(out)}.part.png"
    fig.savefig(tmp)
    plt.close(fig)
    os.replace(tmp, out)
    log.info("%s: %d poses, %d motes", out, len(data.pose_t), len(data.motes))
    return data
