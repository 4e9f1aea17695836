"""BVH reading and forward kinematics to the 13 Samba joints.

The BVH -> joint mapping comes from TOML files in ``configs/bvh/`` (installed as
``samba_configs/bvh``); :func:`load_bvh` picks the first mapping whose names are all in the
file. Output is in the Samba world frame (FORMATS.md): Z up, metres.
"""

from __future__ import annotations

import logging
import os
from dataclasses import dataclass, field
from importlib.resources import files
from pathlib import Path

import numpy as np

from .body import ANKLE_HEIGHT
from .config import ConfigError, read_toml, tomllib
from .skeleton import JOINT_NAMES, J

log = logging.getLogger(__name__)


class BvhError(ValueError):
    """A BVH file cannot be parsed or mapped to the 13 joints."""


@dataclass(frozen=True)
class BvhMapping:
    """Which BVH joint stands for each Samba joint.

    joints: Samba joint name -> candidate BVH names in priority order.
    unit_scale: metres per BVH unit, or None to infer it from the shin length.
    up: the BVH up axis, "y" or "z".
    """

    name: str
    joints: dict[str, tuple[str, ...]]
    unit_scale: float | None = None
    up: str = "y"

    @staticmethod
    def load(path: str | os.PathLike) -> "BvhMapping":
        """Read a mapping TOML (see configs/bvh/*.toml); ConfigError names the file and key."""
        return BvhMapping.from_dict(read_toml(path), str(path))

    @staticmethod
    def from_dict(data: dict, path: str) -> "BvhMapping":
        try:
            joints = {k: tuple(v) for k, v in data["joints"].items()}
        except (KeyError, TypeError, AttributeError):
            raise ConfigError(f"{path}: needs a [joints] table of name -> list of BVH names") from None
        missing = [n for n in JOINT_NAMES if n not in joints]
        if missing:
            raise ConfigError(f"{path} [joints]: no entry for {missing}")
        up = str(data.get("up", "y")).lower()
        if up not in ("y", "z"):
            raise ConfigError(f"{path} [up]: must be 'y' or 'z', not {up!r}")
        scale = data.get("unit_scale")
        return BvhMapping(str(data.get("name", Path(path).stem)), joints,
                          None if scale is None else float(scale), up)

    def resolve(self, names: set[str]) -> list[str] | None:
        """BVH joint names for the 13 joints in JOINT_NAMES order, or None if any is absent."""
        out = []
        for j in JOINT_NAMES:
            hit = next((c for c in self.joints[j] if c in names), None)
            if hit is None:
                return None
            out.append(hit)
        return out


def builtin_mappings() -> list[BvhMapping]:
    """The mappings shipped in ``configs/bvh/``, in a stable (alphabetical) order."""
    folder = files("samba_configs").joinpath("bvh")
    return [BvhMapping.from_dict(tomllib.loads(entry.read_text()), entry.name)
            for entry in sorted(folder.iterdir(), key=lambda e: e.name) if entry.name.endswith(".toml")]


@dataclass
class BvhJoint:
    """name; parent index (-1 for the root); offset (3,) in file units; channel names; first
    column of its channels in the motion table."""

    name: str
    parent: int
    offset: np.ndarray
    channels: list[str] = field(default_factory=list)
    first: int = 0


@dataclass
class BvhDocument:
    """A parsed BVH file: joints in file order (End Sites left out), motion (F, C) channel
    values, frame_time in seconds."""

    joints: list[BvhJoint]
    motion: np.ndarray
    frame_time: float

    def index(self, name: str) -> int:
        """Position of joint ``name`` in ``joints`` (KeyError if absent)."""
        for k, j in enumerate(self.joints):
            if j.name == name:
                return k
        raise KeyError(name)


@dataclass
class BvhTake:
    """Joints of one BVH take in the Samba world frame.

    joints: (F, 13, 3) metres, Z up; t: (F,) seconds from 0; fps: frames per second;
    mapping: name of the mapping used; source: the file.
    """

    joints: np.ndarray
    t: np.ndarray
    fps: float
    mapping: str
    source: str


def parse_bvh_text(text: str, path: str = "<text>") -> BvhDocument:
    """Parse BVH text (any channel order, position channels on any joint).

    Raises BvhError naming ``path`` on malformed input."""
    tokens = text.split()
    joints: list[BvhJoint] = []
    stack: list[int | None] = []  # None marks an End Site block
    pending: int | None = None
    n_chan = 0
    try:
        if not tokens or tokens[0] != "HIERARCHY":
            raise BvhError(f"{path}: does not start with HIERARCHY")
        i = 1
        while tokens[i] != "MOTION":
            tok = tokens[i]
            if tok in ("ROOT", "JOINT"):
                parent = next((k for k in reversed(stack) if k is not None), -1)
                joints.append(BvhJoint(tokens[i + 1], parent, np.zeros(3)))
                pending = len(joints) - 1
                i += 2
            elif tok == "End":
                pending = None
                i += 2
            elif tok == "{":
                stack.append(pending)
                i += 1
            elif tok == "}":
                stack.pop()
                i += 1
            elif tok == "OFFSET":
                if stack[-1] is not None:
                    joints[stack[-1]].offset = np.array([float(x) for x in tokens[i + 1:i + 4]])
                i += 4
            elif tok == "CHANNELS":
                k = int(tokens[i + 1])
                jt = joints[stack[-1]]  # type: ignore[index]
                jt.channels = tokens[i + 2:i + 2 + k]
                jt.first = n_chan
                n_chan += k
                i += 2 + k
            else:
                raise BvhError(f"{path}: unexpected token {tok!r} in HIERARCHY")
        if tokens[i + 1] != "Frames:" or tokens[i + 3] != "Frame" or tokens[i + 4] != "Time:":
            raise BvhError(f"{path}: MOTION header is not 'Frames: N' / 'Frame Time: T'")
        n_frames = int(tokens[i + 2])
        frame_time = float(tokens[i + 5])
        values = np.array(tokens[i + 6:], dtype=np.float64)
    except (IndexError, ValueError, TypeError) as exc:
        if isinstance(exc, BvhError):
            raise
        raise BvhError(f"{path}: malformed BVH ({exc})") from None
    if values.size != n_frames * n_chan or n_chan == 0:
        raise BvhError(f"{path}: MOTION has {values.size} values, expected {n_frames} x {n_chan}")
    if frame_time <= 0:
        raise BvhError(f"{path}: Frame Time must be positive")
    return BvhDocument(joints, values.reshape(n_frames, n_chan), frame_time)


def read_bvh(path: str | os.PathLike) -> BvhDocument:
    """Read and parse a BVH file; BvhError names the file on any problem."""
    p = Path(path)
    try:
        text = p.read_text(errors="replace")
    except OSError as exc:
        raise BvhError(f"{p}: cannot read ({exc.strerror})") from None
    if not text.strip():
        raise BvhError(f"{p}: empty file")
    return parse_bvh_text(text, str(p))


def _axis_rot(axis: str, deg: np.ndarray) -> np.ndarray:
    """(F,) degrees -> (F, 3, 3) rotation about 'X', 'Y' or 'Z'."""
    a = np.radians(deg)
    c, s = np.cos(a), np.sin(a)
    R = np.zeros(a.shape + (3, 3))
    k = "XYZ".index(axis)
    i, j = (k + 1) % 3, (k + 2) % 3
    R[:, k, k] = 1
    R[:, i, i] = c
    R[:, j, j] = c
    R[:, j, i] = s
    R[:, i, j] = -s
    return R


def forward_kinematics(doc: BvhDocument, wanted: list[int] | None = None) -> np.ndarray:
    """Global positions (F, len(wanted), 3) in file units of the joints ``wanted`` (indices into
    doc.joints; default all). Rotations compose in channel order; only the needed chains are
    computed."""
    joints, motion = doc.joints, doc.motion
    wanted = list(range(len(joints))) if wanted is None else wanted
    need: set[int] = set()
    for w in wanted:
        while w >= 0 and w not in need:
            need.add(w)
            w = joints[w].parent
    F = motion.shape[0]
    pos: dict[int, np.ndarray] = {}
    rot: dict[int, np.ndarray] = {}
    for idx in sorted(need):  # parents always come before children in a BVH
        jt = joints[idx]
        local_t = np.broadcast_to(jt.offset, (F, 3)).copy()
        R = np.broadcast_to(np.eye(3), (F, 3, 3)).copy()
        for c, ch in enumerate(jt.channels):
            col = motion[:, jt.first + c]
            if ch.endswith("position"):
                local_t[:, "XYZ".index(ch[0].upper())] += col
            elif ch.endswith("rotation"):
                R = R @ _axis_rot(ch[0].upper(), col)
        if jt.parent < 0:
            pos[idx], rot[idx] = local_t, R
        else:
            pr = rot[jt.parent]
            pos[idx] = pos[jt.parent] + np.einsum("fij,fj->fi", pr, local_t)
            rot[idx] = pr @ R
    return np.stack([pos[w] for w in wanted], axis=1)


def _infer_scale(joints_units: np.ndarray) -> float:
    """Metres per unit from the median shin length (typical adult shin 0.36-0.50 m)."""
    shin = np.nanmedian(np.linalg.norm(joints_units[:, J["left_knee"]] - joints_units[:, J["left_ankle"]], axis=-1))
    if not np.isfinite(shin) or shin <= 0:
        raise BvhError("cannot infer units: zero shin length")
    candidates = np.array([1.0, 0.01, 0.001, 0.0254, 0.0254 / 0.45])
    return float(candidates[np.argmin(np.abs(np.log(shin * candidates / 0.42)))])


def load_bvh(path: str | os.PathLike, mapping: BvhMapping | str | os.PathLike | None = None,
             unit_scale: float | None = None) -> BvhTake:
    """Read a BVH file and return its 13 joints in the Samba world frame (Z up, metres).

    mapping: a BvhMapping, a path to a mapping TOML, or None to try the built-in mappings.
    unit_scale: metres per BVH unit; overrides the mapping's (None: mapping's, else inferred).
    The vertical position is left as in the file (see :func:`put_on_floor`).
    """
    p = Path(path)
    doc = read_bvh(p)
    names = {j.name for j in doc.joints}
    if mapping is None:
        candidates = builtin_mappings()
    elif isinstance(mapping, BvhMapping):
        candidates = [mapping]
    else:
        candidates = [BvhMapping.load(mapping)]
    chosen, resolved = None, None
    for m in candidates:
        resolved = m.resolve(names)
        if resolved is not None:
            chosen = m
            break
    if chosen is None or resolved is None:
        tried = ", ".join(m.name for m in candidates)
        raise BvhError(f"{p}: no mapping fits its joint names (tried {tried}); "
                       f"write one like configs/bvh/cmu_classic.toml")
    pts = forward_kinematics(doc, [doc.index(n) for n in resolved])
    if chosen.up == "y":  # BVH (X right, Y up, Z front) -> Samba (X, -Z, Y)
        pts = np.stack([pts[..., 0], -pts[..., 2], pts[..., 1]], axis=-1)
    scale = unit_scale or chosen.unit_scale or _infer_scale(pts)
    pts = pts * scale
    fps = 1.0 / doc.frame_time
    t = np.arange(pts.shape[0]) / fps
    log.debug("%s: %d frames at %.1f fps, mapping %s, %.4g m/unit", p, len(t), fps, chosen.name, scale)
    return BvhTake(pts, t, fps, chosen.name, str(p))


def floor_ankle_height(joints: np.ndarray) -> float:
    """Height (m) of a take's ankles on its floor: the 2nd percentile over frames of the lower
    ankle (joints (F, 13, 3)), so a few glitchy frames do not count."""
    ankles = joints[:, [J["left_ankle"], J["right_ankle"]], 2]
    return float(np.nanpercentile(np.nanmin(ankles, axis=1), 2))


def put_on_floor(joints: np.ndarray, ankle_height: float = ANKLE_HEIGHT) -> np.ndarray:
    """Shift a take vertically so its lowest ankles (:func:`floor_ankle_height`) stand
    ``ankle_height`` m above z = 0. joints: (F, 13, 3) metres."""
    out = joints.copy()
    out[..., 2] += ankle_height - floor_ankle_height(joints)
    return out


def resample(joints: np.ndarray, t: np.ndarray, fps: float) -> tuple[np.ndarray, np.ndarray]:
    """Linear resampling of (F, 13, 3) joints at times t (F,) to ``fps``; returns (joints, t)."""
    if len(t) < 2:
        return joints.copy(), t.copy()
    t_new = np.arange(t[0], t[-1] + 1e-9, 1.0 / fps)
    flat = joints.reshape(len(t), -1)
    out = np.empty((len(t_new), flat.shape[1]))
    for c in range(flat.shape[1]):
        out[:, c] = np.interp(t_new, t, flat[:, c])
    return out.reshape(len(t_new), *joints.shape[1:]), t_new
