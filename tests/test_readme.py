"""The README, run as written (issue 13): every command it shows exists with the options it uses,
and the walk-through works end to end on a small simulated take.

What is checked
---------------
1. ``test_readme_commands_and_options_exist``: every ``samba-*`` command the README shows (inline
   code, fenced ``sh`` blocks, the Commands table) is a console script of ``pyproject.toml``,
   installed next to this Python, and each option it is written with appears in that
   command's ``--help`` (of the subcommand, for ``samba-db build`` etc.). Bare options of the
   walk-through (``--preview DIR``, ``--out take.c3d``) must belong to a command it named
   before them (the last one first); bare options of the Commands section (``--help``, ``-v``:
   "every command has ...") to every command of the table (to each subcommand when the
   program itself lacks it); ``?key=`` spans of a table row must appear in that row's ``--help``.
   The ``--help`` texts come from the console scripts' entry points in one subprocess.
2. The commands themselves, through ``bash -c`` with the venv's console scripts on ``PATH``,
   in a temporary folder, each under a timeout. Each command is taken from the README
   (:func:`readme_command` finds it by its beginning and fails if the README no longer shows
   it) and changed only by :func:`sub`, which fails if the text to replace is gone: paths, free
   ports instead of 7447/8080, 127.0.0.1 instead of 0.0.0.0, a 1 s take, 600 wand frames
   instead of 2400, a 5 s demo, ``?start=T`` on the file motes so they play in step.
   Results are checked for a sane outcome: frames solved and close to the simulated truth,
   ``samba-replay --out`` equal to the poses it replays (the live poses a recording holds, of
   the live server and of ``samba-process``, whose own output is solved from both ends),
   exports read back by readers that share no code with Samba (a BVH parser with its own
   forward kinematics below, ezc3d and the pure-Python ``c3d`` package, a strict TRC parser,
   the ``csv`` module, ``mcap``'s reader), the wand calibration close to the simulated rig.

Extending it when the README gains a command
--------------------------------------------
* A new ``samba-*`` command or option anywhere in the README is covered by (1) with no change
  here; a command with subcommands is recognised from the ``{a,b}`` choices in its ``--help``.
* To run it as well: add a test (or a step to the closest one) that gets the text with
  ``readme_command("samba-new --opt")``, adapts paths/ports with ``sub(...)``, runs it with
  ``run(cmd, cwd)`` (exit code checked, output returned) and checks its output with a reader
  that does not import ``samba_*``. Keep each step to a few seconds (small takes, ``--seconds``,
  ``--duration``): the whole module should stay under about two minutes.
* Commands that need hardware (``v4l2:``, serial ports), take minutes (``samba-db build`` of
  the shipped database) or change the repository are only checked by (1); list them in
  ``NOT_RUN`` with the reason.

Tests that need the shared CMU clips skip with :data:`tests.shared_data.CMU_SKIP`.
"""

from __future__ import annotations

import csv
import os
import re
import shlex
import signal
import socket
import subprocess
import sys
import time
import urllib.request
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pytest

from tests.shared_data import CMU_DIR, CMU_SKIP

try:
    import tomllib
except ModuleNotFoundError:  # Python 3.10
    import tomli as tomllib

REPO = Path(__file__).resolve().parents[1]
README = REPO / "README.md"
BIN = Path(sys.executable).parent  # the venv's console scripts
CLIP = "002_03.bvh"  # a short CMU clip (walk); the take is cut to --seconds 1 anyway

#: README commands that are only --help-checked, and why
NOT_RUN = {
    "samba-mote --source v4l2:": "needs a camera (the file-source form is run live)",
    "samba-gateway": "needs a serial port",
    "samba-db build ../shared": "rebuilds the shipped database: minutes",
    "--tls": "mutual TLS is exercised by tests/server/test_security.py",
    "bash scripts/": "the two set-up scripts install and run this whole suite",
    "samba-chaos": "the fault harness has its own tests (tests/server/test_chaos.py)",
    "table variants": "samba-sim ... --seconds 10 out/, samba-process ... --fps 30, samba-calibrate "
                      "extrinsics wand/: the walk-through's forms of the same commands are run",
}


# ----------------------------------------------------------------------------------------------
# README parsing

@dataclass
class Snippet:
    text: str
    section: str  # the "## " heading it is under
    line: int
    fenced: bool
    row: str | None = None  # Commands table: the command of the row
    example: bool = False  # Commands table: in the example column (the last one)


@dataclass
class Command:
    text: str
    prog: str
    tokens: list[str]
    line: int
    options: list[str] = field(default_factory=list)


def readme_text() -> str:
    return README.read_text(encoding="utf-8")


def snippets(text: str | None = None) -> list[Snippet]:
    """Code of the README: each line of a fenced block (comments dropped) and each inline span."""
    out: list[Snippet] = []
    section, fence = "", None
    for n, line in enumerate((text or readme_text()).splitlines(), 1):
        if fence is not None:
            if line.startswith("```"):
                fence = None
            elif fence in ("", "sh", "bash", "console"):
                code = line.split(" #", 1)[0].strip()
                if code:
                    out.append(Snippet(code, section, n, True))
            continue
        if line.startswith("```"):
            fence = line[3:].strip()
            continue
        if line.startswith("## "):
            section = line[3:].strip()
        m = re.match(r"\|\s*`(samba-[a-z]+)`\s*\|", line)
        if m:  # a row of the Commands table: command | what it does | example
            cells = line.strip().strip("|").split("|")
            for k, cell in enumerate(cells):
                for span in re.findall(r"`([^`]+)`", cell):
                    out.append(Snippet(span.strip(), section, n, False, m.group(1), k == len(cells) - 1))
            continue
        for span in re.findall(r"`([^`]+)`", line):
            out.append(Snippet(span.strip(), section, n, False))
    return out


def parse_command(text: str, line: int = 0) -> Command | None:
    """A ``samba-*`` command line: program, tokens (``[--opt X]`` brackets dropped), options."""
    if not re.match(r"samba-[a-z]+(\s|$)", text):
        return None
    tokens = shlex.split(re.sub(r"\[(-[^\]]*)\]", r"\1", text), comments=True)
    opts = [t.split("=", 1)[0] for t in tokens[1:] if re.match(r"--?[A-Za-z]", t)]
    return Command(text, tokens[0], tokens, line, opts)


def readme_commands() -> list[Command]:
    return [c for s in snippets() if (c := parse_command(s.text, s.line))]


def readme_command(prefix: str) -> str:
    """The first README command that starts with ``prefix`` (the test fails if there is none)."""
    for c in readme_commands():
        if c.text.startswith(prefix):
            return c.text
    pytest.fail(f"README.md no longer shows a command starting with {prefix!r}: "
                "update tests/test_readme.py to run what it shows now")


def sub(cmd: str, old: str, new: str) -> str:
    """``cmd`` with ``old`` replaced; fails if the README's command no longer contains ``old``."""
    assert old in cmd, f"README command {cmd!r} no longer contains {old!r}: update tests/test_readme.py"
    return cmd.replace(old, new)


# ----------------------------------------------------------------------------------------------
# running the console scripts

def _env() -> dict[str, str]:
    return dict(os.environ, PATH=f"{BIN}{os.pathsep}{os.environ.get('PATH', '')}", OPENBLAS_NUM_THREADS="1",
                MPLBACKEND="Agg", PYTHONUNBUFFERED="1")


def run(cmd: str, cwd: Path, timeout: float = 300, codes: tuple[int, ...] = (0,)) -> subprocess.CompletedProcess:
    """Run one shell command line as a user would; check its exit code; stdout+stderr in ``.out``."""
    try:
        r = subprocess.run(["bash", "-c", cmd], cwd=cwd, env=_env(), capture_output=True, text=True,
                           timeout=timeout, stdin=subprocess.DEVNULL)
    except subprocess.TimeoutExpired as exc:
        pytest.fail(f"`{cmd}` did not finish within {timeout} s; output so far:\n{exc.stdout}\n{exc.stderr}")
    r.out = (r.stdout or "") + (r.stderr or "")
    assert r.returncode in codes, f"`{cmd}` exited {r.returncode} (expected {codes}):\n{r.out[-3000:]}"
    return r


_HELP: dict[tuple[str, ...], str] = {}

#: prints ``--help`` of each command path given as JSON, through the console scripts' entry points
#: (one interpreter for all of them: ~1 s each otherwise); run as a user would, in a subprocess
_HELP_SCRIPT = r"""
import contextlib, importlib, io, json, sys
try:
    import tomllib
except ModuleNotFoundError:
    import tomli as tomllib
scripts = tomllib.load(open(sys.argv[1], "rb"))["project"]["scripts"]
out = {}
for path in json.loads(sys.argv[2]):
    mod, func = scripts[path[0]].split(":")
    buf, code = io.StringIO(), None
    try:
        with contextlib.redirect_stdout(buf), contextlib.redirect_stderr(buf):
            code = getattr(importlib.import_module(mod), func)([*path[1:], "--help"])
    except SystemExit as exc:
        code = exc.code
    except Exception as exc:
        code = repr(exc)
    out[" ".join(path)] = [code, buf.getvalue()]
print(json.dumps(out))
"""


def load_helps(paths: list[tuple[str, ...]]) -> None:
    """``--help`` of every command path not seen yet, in one subprocess."""
    import json

    todo = sorted({p for p in paths if p not in _HELP})
    if not todo:
        return
    r = subprocess.run([sys.executable, "-c", _HELP_SCRIPT, str(REPO / "pyproject.toml"), json.dumps(todo)],
                       env=_env(), capture_output=True, text=True, timeout=300, stdin=subprocess.DEVNULL, cwd=REPO)
    assert r.returncode == 0, r.stderr[-3000:]
    for key, (code, text) in json.loads(r.stdout.strip().splitlines()[-1]).items():
        assert code in (0, None), f"`{key} --help` exited {code}:\n{text[-2000:]}"
        _HELP[tuple(key.split(" "))] = text


def help_text(*argv: str) -> str:
    if argv not in _HELP:
        load_helps([argv])
    return _HELP[argv]


def subcommands(help_out: str) -> set[str]:
    """Choices of a positional (subcommands) from the 'positional arguments' part of --help."""
    part = help_out.split("positional arguments:", 1)[-1].split("options:", 1)[0] if "positional arguments:" in help_out else ""
    found: set[str] = set()
    for m in re.finditer(r"^\s+\{([\w,-]+)\}", part, re.M):
        found.update(m.group(1).split(","))
    return found


def help_path(cmd: Command) -> tuple[str, ...]:
    """The program plus the subcommands the command names (``samba-db build``)."""
    path = (cmd.prog,)
    for tok in cmd.tokens[1:]:
        if tok.startswith("-") or tok not in subcommands(help_text(*path)):
            break
        path += (tok,)
    return path


def has_option(help_out: str, opt: str) -> bool:
    return re.search(rf"(?<![\w-]){re.escape(opt)}(?![\w-])", help_out) is not None


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def wait_for(path: Path, text: str, proc: subprocess.Popen, timeout: float) -> None:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if path.exists() and text in path.read_text(errors="replace"):
            return
        if proc.poll() is not None:
            break
        time.sleep(0.1)
    pytest.fail(f"no {text!r} from {proc.args} within {timeout} s:\n{path.read_text(errors='replace') if path.exists() else ''}")


def stop(proc: subprocess.Popen, log: Path, timeout: float = 60) -> int:
    """Ctrl-C, as the README says; kill only if it does not stop."""
    if proc.poll() is None:
        proc.send_signal(signal.SIGINT)
    try:
        return proc.wait(timeout=timeout)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait(10)
        pytest.fail(f"{proc.args} did not stop within {timeout} s of Ctrl-C:\n{log.read_text(errors='replace')}")


# ----------------------------------------------------------------------------------------------
# independent readers (no samba_* imports)

def load_npz(path: Path) -> dict[str, np.ndarray]:
    with np.load(path, allow_pickle=False) as z:
        return {k: z[k] for k in z.files}


def solved(joints: np.ndarray) -> np.ndarray:
    return np.isfinite(joints).all(axis=(1, 2))


def same_poses(a: Path, b: Path, atol: float = 1e-9) -> None:
    """Same frames, same unsolved frames, same joints (``atol``: 1e-6 m for poses read back from a
    recording, whose pose messages hold float32)."""
    ja, jb = load_npz(a), load_npz(b)
    assert ja["joints"].shape == jb["joints"].shape, f"{a.name} {ja['joints'].shape} vs {b.name} {jb['joints'].shape}"
    np.testing.assert_array_equal(np.isnan(ja["joints"]), np.isnan(jb["joints"]), err_msg=f"{a.name} vs {b.name}")
    np.testing.assert_allclose(np.nan_to_num(ja["joints"]), np.nan_to_num(jb["joints"]), atol=atol, rtol=0,
                               err_msg=f"{a.name} vs {b.name}")
    np.testing.assert_allclose(ja["t"] - ja["t"][0], jb["t"] - jb["t"][0], atol=1e-6)


def read_bvh_fk(path: Path) -> tuple[dict[str, np.ndarray], float]:
    """A strict BVH reader with its own forward kinematics: joint name -> (F, 3) positions, frame time."""
    toks = path.read_text().split()
    i = 0

    def take(expected: str | None = None) -> str:
        nonlocal i
        tok = toks[i]
        i += 1
        if expected is not None and tok != expected:
            raise AssertionError(f"{path.name}: expected {expected!r}, got {tok!r} (token {i})")
        return tok

    joints: list[tuple[str, int, np.ndarray, list[str]]] = []  # name, parent, offset, channels

    def joint(parent: int, name: str) -> None:
        take("{")
        take("OFFSET")
        offset = np.array([float(take()) for _ in range(3)])
        take("CHANNELS")
        chans = [take() for _ in range(int(take()))]
        assert all(c in {"Xposition", "Yposition", "Zposition", "Xrotation", "Yrotation", "Zrotation"}
                   for c in chans), chans
        me = len(joints)
        joints.append((name, parent, offset, chans))
        while toks[i] != "}":
            kind = take()
            if kind == "JOINT":
                joint(me, take())
            elif kind == "End":
                take("Site"), take("{"), take("OFFSET"), [float(take()) for _ in range(3)], take("}")
            else:
                raise AssertionError(f"{path.name}: unexpected {kind!r}")
        take("}")

    take("HIERARCHY")
    take("ROOT")
    joint(-1, take())
    take("MOTION")
    take("Frames:")
    n = int(take())
    take("Frame")
    take("Time:")
    dt = float(take())
    width = sum(len(j[3]) for j in joints)
    values = np.array(toks[i:], dtype=float)
    assert values.size == n * width, f"{path.name}: {values.size} motion values, expected {n} x {width}"
    motion = values.reshape(n, width)

    def rot(axis: str, deg: np.ndarray) -> np.ndarray:
        a = np.radians(deg)
        c, s = np.cos(a), np.sin(a)
        m = np.zeros((len(a), 3, 3))
        k = "XYZ".index(axis)
        p, q = (k + 1) % 3, (k + 2) % 3  # cyclic, so that Y turns Z towards X
        m[:, k, k] = 1
        m[:, p, p], m[:, q, q], m[:, p, q], m[:, q, p] = c, c, -s, s
        return m

    world_r: list[np.ndarray] = []
    world_p: list[np.ndarray] = []
    col = 0
    out: dict[str, np.ndarray] = {}
    for name, parent, offset, chans in joints:
        local_t = np.tile(offset, (n, 1))
        local_r = np.tile(np.eye(3), (n, 1, 1))
        for c in chans:  # rotations compose in channel order (intrinsic), positions add to the offset
            if c.endswith("position"):
                local_t[:, "XYZ".index(c[0])] += motion[:, col]
            else:
                local_r = local_r @ rot(c[0], motion[:, col])
            col += 1
        if parent < 0:
            r, p = local_r, local_t
        else:
            r = world_r[parent] @ local_r
            p = world_p[parent] + np.einsum("fij,fj->fi", world_r[parent], local_t)
        world_r.append(r)
        world_p.append(p)
        out[name] = p
    return out, dt


def read_trc(path: Path) -> tuple[dict[str, str], list[str], np.ndarray, np.ndarray]:
    """A strict TRC (PathFileType 4) reader: header, marker names, times (F,), data (F, M, 3) NaN = empty."""
    lines = path.read_text().split("\n")
    first = lines[0].split("\t")
    assert first[:3] == ["PathFileType", "4", "(X/Y/Z)"], first
    keys, vals = lines[1].split("\t"), lines[2].split("\t")
    assert keys[:8] == ["DataRate", "CameraRate", "NumFrames", "NumMarkers", "Units", "OrigDataRate",
                        "OrigDataStartFrame", "OrigNumFrames"], keys
    head = dict(zip(keys, vals))
    nf, nm = int(head["NumFrames"]), int(head["NumMarkers"])
    names_row = lines[3].split("\t")
    assert names_row[:2] == ["Frame#", "Time"]
    names = [x for x in names_row[2:] if x]
    assert len(names) == nm, f"{nm} markers in the header, {len(names)} names"
    sub_row = lines[4].split("\t")[2:]
    assert sub_row[:3 * nm] == [f"{a}{k + 1}" for k in range(nm) for a in "XYZ"]
    rows = [ln.split("\t") for ln in lines[5:] if ln.strip()]
    assert len(rows) == nf, f"NumFrames {nf}, {len(rows)} rows"
    data = np.full((nf, nm, 3), np.nan)
    t = np.zeros(nf)
    for k, r in enumerate(rows):
        assert int(r[0]) == k + 1 and len(r) <= 2 + 3 * nm, r[:3]
        t[k] = float(r[1])
        for m in range(nm):
            xyz = r[2 + 3 * m: 5 + 3 * m]
            if any(xyz):
                data[k, m] = [float(v) for v in xyz]
    return head, names, t, data


# ----------------------------------------------------------------------------------------------
# 1. every command and option the README shows exists

def test_readme_commands_and_options_exist() -> None:
    scripts = tomllib.loads((REPO / "pyproject.toml").read_text())["project"]["scripts"]
    snips = snippets()
    cmds = [c for s in snips if (c := parse_command(s.text, s.line))]
    assert len({c.prog for c in cmds}) >= 10, "the README's commands were not found: has its layout changed?"
    problems: list[str] = []
    for prog in sorted({c.prog for c in cmds}):
        if prog not in scripts:
            problems.append(f"{prog}: not a console script in pyproject.toml [project.scripts]")
        elif not (BIN / prog).exists():
            problems.append(f"{prog}: not installed in {BIN} (pip install -e .)")
    if problems:
        pytest.fail("\n".join(problems))
    load_helps([(c.prog,) for c in cmds])
    load_helps([(c.prog, c.tokens[1]) for c in cmds if len(c.tokens) > 1 and c.tokens[1] in subcommands(help_text(c.prog))])

    checks: list[tuple[tuple[str, ...], str, int]] = []  # (help path, option, README line)
    for c in cmds:
        path = help_path(c)
        checks += [(path, o, c.line) for o in c.options]
    # bare options: walk-through -> a command it named before them; Commands section -> every
    # command of the table (its first paragraph speaks of every command); table rows -> their command
    table = sorted({s.row for s in snips if s.row})
    assert len(table) >= 10, "the Commands table was not found"
    walk: list[Command] = []  # commands of the walk-through so far
    for s in snips:
        if (c := parse_command(s.text, s.line)):
            if s.section.startswith("A capture session"):
                walk.append(c)
            continue
        opt = re.match(r"(--?[A-Za-z][\w-]*)", s.text)
        if s.row and s.text.startswith("?"):
            key = s.text[1:].split("=", 1)[0]
            if not re.search(rf"[?&]{re.escape(key)}=", help_text(s.row)):
                problems.append(f"README line {s.line}: {s.row} --help does not mention {s.text!r}")
        if not opt or s.fenced:
            continue
        if s.row:
            if s.example:
                checks.append(((s.row,), opt.group(1), s.line))
        elif s.section == "Commands":  # every command: the program, else each of its subcommands
            for prog in table:
                subs = sorted(subcommands(help_text(prog)))
                if subs and not has_option(help_text(prog), opt.group(1)):
                    load_helps([(prog, sc) for sc in subs])
                    checks += [((prog, sc), opt.group(1), s.line) for sc in subs]
                else:
                    checks.append(((prog,), opt.group(1), s.line))
        elif s.section.startswith("A capture session") and walk:
            # the command named just before ("--out take.c3d" after samba-export), else one the
            # walk-through showed earlier ("run the motes with --unlabelled" after samba-calibrate)
            paths = [help_path(c) for c in reversed(walk)]
            if not any(has_option(help_text(*p), opt.group(1)) for p in paths):
                problems.append(f"README line {s.line}: no command of the walk-through so far "
                                f"({', '.join(sorted({' '.join(p) for p in paths}))}) has an option {opt.group(1)}")
    for path, opt, line in checks:
        if not has_option(help_text(*path), opt):
            problems.append(f"README line {line}: `{' '.join(path)}` has no option {opt} (not in its --help)")
    assert not problems, "README.md names options the commands do not have:\n" + "\n".join(sorted(set(problems)))


def test_two_commands_scripts_exist() -> None:
    text = readme_text()
    for script in re.findall(r"^bash (scripts/\S+\.sh)", text, re.M):
        assert (REPO / script).is_file(), f"README runs {script}, which does not exist"
    if "--duration" in text.split("## Two commands", 1)[-1].split("##", 1)[0]:
        assert '"$@"' in (REPO / "scripts" / "demo.sh").read_text(), "demo.sh does not pass --duration on"


# ----------------------------------------------------------------------------------------------
# 2. the commands, run as written on a small simulated take

@pytest.fixture(scope="module")
def take(tmp_path_factory) -> Path:
    """``samba-sim`` then ``samba-process`` as the README's "Without cameras" paragraph writes them."""
    if not (CMU_DIR / CLIP).is_file():
        pytest.skip(CMU_SKIP)
    d = tmp_path_factory.mktemp("readme")
    os.symlink(CMU_DIR / CLIP, d / "clip.bvh")
    cmd = readme_command("samba-sim --bvh clip.bvh")
    run(cmd + " --seconds 1", d, timeout=120)  # keep the take short: 1 s of clip after the lead-in
    assert (d / "sim" / "calibration.toml").is_file() and len(list((d / "sim").glob("cam*.avi"))) == 4
    cmd = readme_command("samba-process sim/calibration.toml")
    assert any(c.prog == "samba-process" and "--record" in c.options for c in readme_commands()), \
        "the README no longer shows samba-process --record"
    r = run(cmd + " --record take.mcap", d, timeout=600, codes=(0, 3))  # 3: written, < half solved (documented)
    j, truth = load_npz(d / "joints.npz"), load_npz(d / "sim" / "joints.npz")
    ok = solved(j["joints"])
    assert len(j["t"]) == len(truth["t"]), f"{len(j['t'])} frames for {len(truth['t'])} rendered"
    assert ok.sum() > 0, f"samba-process solved no frame:\n{r.out}"
    if r.returncode == 0:
        assert ok.sum() >= 0.5 * len(ok)
    err = np.linalg.norm(j["joints"][ok] - truth["joints"][ok], axis=-1)
    assert np.median(err) < 0.05, f"median joint error {np.median(err) * 100:.1f} cm vs the simulated truth"
    print(f"samba-process: {ok.sum()}/{len(ok)} frames solved, median error {np.median(err) * 1000:.1f} mm")
    return d


def test_replay_inspect_and_exports(take: Path) -> None:
    d = take
    frames = len(load_npz(d / "joints.npz")["t"])
    # samba-replay --out re-runs the recording: exactly the live poses it holds (read back below)
    run(sub(readme_command("samba-replay take.mcap --out"), "joints.npz", "replay.npz"), d)

    # samba-inspect, walk-through form and table form
    r = run(readme_command("samba-inspect take.mcap --plot"), d)
    assert (d / "take.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    dur = float(re.search(r"take\.mcap: ([\d.e+]+) s", r.out).group(1))
    assert 0.5 * frames / 60 < dur < 2 * frames / 60 + 1, f"duration {dur} s for {frames} frames at 60 fps"
    for lat in re.findall(r"latency p50 ([\d.e+-]+) ms", r.out):
        assert float(lat) < 1000, f"latency p50 {lat} ms"
    for cam in ("cam0", "cam1", "cam2", "cam3"):
        assert f"mote {cam}" in r.out
    cmd = sub(sub(readme_command("samba-inspect take.mcap --export"), "joints.npz", "inspect.npz"),
              "take.png", "take2.png")
    run(cmd, d)
    same_poses(d / "replay.npz", d / "inspect.npz", atol=1e-6)  # the recorded live poses (float32)
    # samba-process wrote the take solved from both ends: the same frames, close to the live poses
    out, live = load_npz(d / "joints.npz"), load_npz(d / "inspect.npz")
    np.testing.assert_allclose(out["t"] - out["t"][0], live["t"] - live["t"][0], atol=1e-6)
    both = solved(out["joints"]) & solved(live["joints"])
    assert both.sum() >= 0.9 * solved(live["joints"]).sum()
    assert np.median(np.linalg.norm(out["joints"][both] - live["joints"][both], axis=-1)) < 0.02
    with open(d / "out.csv", newline="") as fh:
        assert len(list(csv.reader(fh))) == frames + 1

    # mcap's own reader: schemas, chunk index, every message
    from mcap.reader import make_reader

    with open(d / "take.mcap", "rb") as fh:
        reader = make_reader(fh)
        summary = reader.get_summary()
        assert summary is not None and summary.chunk_indexes, "take.mcap has no summary/chunk index"
        assert all(ch.schema_id in summary.schemas for ch in summary.channels.values() if ch.message_encoding != "json")
        assert sum(1 for _ in reader.iter_messages()) == summary.statistics.message_count > 0

    # samba-export: step 5 of the walk-through, then the table's take.mcap form
    export = readme_command("samba-export joints.npz --out take.bvh")
    outs = ["take.bvh"] + [s.text.split()[1] for s in snippets()
                           if s.section.startswith("A capture session") and s.text.startswith("--out take.")]
    assert {Path(o).suffix for o in outs} >= {".bvh", ".c3d", ".trc", ".csv"}, outs
    for o in outs:
        run(sub(export, "take.bvh", o), d)
    run(sub(readme_command("samba-export take.mcap --out take.c3d"), "take.c3d", "take_mcap.c3d"), d)
    check_exports(d)


def check_exports(d: Path) -> None:
    jz = load_npz(d / "joints.npz")
    joints, t = jz["joints"], jz["t"]
    names = [str(n) for n in jz["joint_names"]]
    n = len(t)
    ok = solved(joints)

    # BVH: Y up, cm, facing -Z (bvh = 100 (x, z, -y)); FK of our own reader
    pos, dt = read_bvh_fk(d / "take.bvh")
    assert dt == pytest.approx(1 / 60, rel=1e-4)
    on = {"LeftUpLeg": "left_hip", "LeftLeg": "left_knee", "LeftFoot": "left_ankle", "RightUpLeg": "right_hip",
          "RightLeg": "right_knee", "RightFoot": "right_ankle", "Head": "head", "LeftArm": "left_shoulder",
          "LeftForeArm": "left_elbow", "LeftHand": "left_wrist", "RightArm": "right_shoulder",
          "RightForeArm": "right_elbow", "RightHand": "right_wrist"}
    assert set(on) <= set(pos), sorted(pos)
    for b, s in on.items():
        p = pos[b]
        assert p.shape == (n, 3)
        back = np.stack([p[:, 0], -p[:, 2], p[:, 1]], -1) / 100.0
        err = np.linalg.norm(back[ok] - joints[ok, names.index(s)], axis=-1)
        # exact where the bones keep their length; a fixed-length skeleton is cm off where they vary
        assert np.median(err) < 0.001 and err.max() < 0.05, f"BVH {b}: median {np.median(err):.4f} m, max {err.max():.4f} m"

    # C3D by ezc3d and by the pure-Python c3d package: mm, Z up, first 13 points = joints (the
    # recording's export holds its live poses, as samba-inspect --export read them back)
    live = load_npz(d / "inspect.npz")["joints"]
    for name, joints in (("take.c3d", jz["joints"]), ("take_mcap.c3d", live)):
        ok = solved(joints)
        ezc3d = pytest.importorskip("ezc3d")
        c = ezc3d.c3d(str(d / name))
        labels = c["parameters"]["POINT"]["LABELS"]["value"]
        assert labels[:13] == names
        pts = np.transpose(c["data"]["points"][:3], (2, 1, 0)) / 1000.0  # (F, P, 3) m
        assert pts.shape[0] == n
        np.testing.assert_allclose(pts[ok, :13], joints[ok], atol=1e-4)
        assert c["parameters"]["POINT"]["RATE"]["value"][0] == pytest.approx(60.0)
        c3d = pytest.importorskip("c3d")
        with open(d / name, "rb") as fh, warnings.catch_warnings():
            warnings.filterwarnings("ignore", "No analog data")  # the reader's note: Samba writes no analog
            r = c3d.Reader(fh)
            assert [s.strip() for s in r.point_labels][:13] == names
            frames = [p[:13, :3].copy() for _, p, _ in r.read_frames()]
        assert len(frames) == n
        got = np.stack(frames) / 1000.0
        np.testing.assert_allclose(got[ok], joints[ok], atol=1e-4)

    joints, ok = jz["joints"], solved(jz["joints"])

    # TRC: OpenSim axes, opensim = 1000 (y, z, x) mm
    head, mnames, tt, data = read_trc(d / "take.trc")
    assert head["Units"] == "mm" and float(head["DataRate"]) == pytest.approx(60.0)
    assert mnames[:13] == names and data.shape[0] == n
    np.testing.assert_allclose(tt, t - t[0], atol=1e-4)
    np.testing.assert_allclose(data[ok, :13], 1000 * joints[ok][..., [1, 2, 0]], atol=1e-2)
    if (~ok).any():  # unsolved frames: empty fields, not numbers
        assert np.isnan(data[~ok, :13]).any(axis=(1, 2)).all()

    # CSV: t, then x/y/z per joint in metres, empty where unsolved
    with open(d / "take.csv", newline="") as fh:
        rows = list(csv.reader(fh))
    assert rows[0] == ["t"] + [f"{j}_{a}" for j in names for a in "xyz"]
    assert len(rows) == n + 1
    vals = np.array([[float(v) if v else np.nan for v in r] for r in rows[1:]])
    np.testing.assert_allclose(vals[:, 0], t, atol=1e-6)
    np.testing.assert_allclose(vals[:, 1:].reshape(n, 13, 3), joints, atol=1e-6, equal_nan=True)


def test_reconstruct_subject_db_and_api(take: Path) -> None:
    d = take
    truth = load_npz(d / "sim" / "joints.npz")
    # samba-db: info of the shipped database, then add a clip to it (a renamed copy: new to it)
    r = run(readme_command("samba-db info default"), d, timeout=120)
    n_clips = int(re.search(r"from (\d+) clips", r.out).group(1))
    (d / "my").mkdir()
    os.symlink(CMU_DIR / CLIP, d / "my" / "readme_clip.bvh")
    run(readme_command("samba-db build my/*.bvh --add-to default"), d, timeout=300)
    r = run("samba-db info my_db.npz", d, timeout=120)
    assert int(re.search(r"from (\d+) clips", r.out).group(1)) == n_clips + 1 and "readme_clip" in r.out

    # samba-reconstruct with every option of the table's example, DB = the database just built
    cmd = sub(sub(sub(readme_command("samba-reconstruct markers.npz"), "markers.npz", "sim/markers.npz"),
                  "--out joints.npz", "--out recon.npz"), "--db DB", "--db my_db.npz")
    cmd = re.sub(r"\[(-[^\]]*)\]", r"\1", cmd)
    r = run(cmd, d, timeout=300, codes=(0, 3))
    j = load_npz(d / "recon.npz")
    ok = solved(j["joints"])
    assert len(ok) == len(truth["t"]) and ok.sum() >= 0.5 * len(ok), r.out
    err = np.linalg.norm(j["joints"][ok] - truth["joints"][ok], axis=-1)
    assert np.median(err) < 0.05, f"samba-reconstruct median error {np.median(err) * 100:.1f} cm"
    with open(d / "joints.csv", newline="") as fh:
        assert len(list(csv.reader(fh))) == len(ok) + 1
    assert re.search(r"frames \d+", r.out) and "bone lengths" in r.out
    run(sub(readme_command("samba-reconstruct sample --out"), "joints.npz", "sample.npz"), d, timeout=300)
    assert solved(load_npz(d / "sample.npz")["joints"]).sum() > 0

    # samba-subject, then samba-reconstruct --subject with it (the table says they use it)
    run(sub(readme_command("samba-subject calibrate markers.npz"), "markers.npz", "sim/markers.npz"), d, timeout=300)
    subj = tomllib.loads((d / "subject.toml").read_text())["subject"]
    assert len(subj["bone_lengths"]) == 8 and all(0.05 < v < 1.0 for v in subj["bone_lengths"].values())
    run("samba-reconstruct sim/markers.npz --out subj.npz --subject subject.toml", d, timeout=300, codes=(0, 3))
    assert solved(load_npz(d / "subj.npz")["joints"]).sum() >= 0.5 * len(ok)

    # the Python API block, with `stream` = the simulated markers
    block = re.search(r"```python\n(.*?)```", readme_text(), re.S).group(1)
    prog = ("import numpy as np\n"
            "z = np.load('sim/markers.npz')\n"
            "stream = list(zip(z['t'], z['markers']))\n"
            "poses = []\n" + block.replace("    pose = rec.solve(markers, t)", "    pose = rec.solve(markers, t); poses.append(pose)")
            + "\nok = [p for p in poses if np.isfinite(p.joints).all()]\n"
            "assert poses and poses[0].joints.shape == (13, 3), poses[:1]\n"
            "assert len(ok) >= len(poses) // 2, (len(ok), len(poses))\n"
            "print(len(ok), len(poses), poses[-1].residual, poses[-1].status)\n")
    assert "pose = rec.solve(markers, t)" in block, "the README's Python API block changed: update the test"
    (d / "api.py").write_text(prog)
    run(f"{shlex.quote(sys.executable)} api.py", d, timeout=300)


def test_keys(tmp_path: Path) -> None:
    run(readme_command("samba-keys init keys/"), tmp_path, timeout=120)
    run(readme_command("samba-keys add-mote keys/"), tmp_path, timeout=120)
    for cam in ("cam0", "cam3", "cam4"):
        assert (tmp_path / "keys" / "motes" / f"{cam}.crt").is_file()
    from cryptography import x509

    cert = x509.load_pem_x509_certificate((tmp_path / "keys" / "motes" / "cam4.crt").read_bytes())
    assert "cam4" in cert.subject.rfc4514_string()


def test_calibration_walkthrough(tmp_path: Path) -> None:
    """Step 2 as written, on the simulated takes it names: board -> intrinsics per camera ->
    wand + L-frame -> extrinsics; camera centres compared with ``calibration_true.toml``."""
    d = tmp_path
    # 150 board views per camera, not the README's 600: OpenCV's calibrateCamera costs about the
    # square of the views (25 s per camera for 600 on the CI machine); the wand step refines them
    run(readme_command("samba-calibrate simulate board") + " --frames 150", d, timeout=120)
    intr = readme_command("samba-calibrate intrinsics --camera cam0")
    for cam in ("cam0", "cam1", "cam2", "cam3"):  # "(repeat for cam1, cam2, ...)"
        run(sub(intr, "cam0", cam), d, timeout=120)
    wand = readme_command("samba-calibrate simulate wand")
    run(re.sub(r"--frames \d+", "--frames 600", wand), d, timeout=180)  # a shorter wave: seconds, not minutes
    run(readme_command("samba-calibrate simulate lframe"), d, timeout=180)
    r = run(readme_command("samba-calibrate extrinsics wand_take/"), d, timeout=300)
    assert "reprojection" in r.out
    import cv2

    def centres(path: Path) -> dict[str, np.ndarray]:
        cal = tomllib.loads(path.read_text())
        out = {}
        for cam in cal.values():
            if isinstance(cam, dict) and "rotation" in cam:
                R = cv2.Rodrigues(np.array(cam["rotation"], float))[0]
                out[cam["name"]] = -R.T @ np.array(cam["translation"], float)
        return out

    got, true = centres(d / "calibration.toml"), centres(d / "wand_take" / "calibration_true.toml")
    assert set(got) == set(true)
    err = {c: float(np.linalg.norm(got[c] - true[c])) for c in true}
    print("samba-calibrate extrinsics: camera centre errors (mm):", {c: round(e * 1000, 1) for c, e in err.items()})
    assert max(err.values()) < 0.05, f"camera centres off by {err} m"


def test_live_capture_session(take: Path) -> None:
    """Step 3-4 with file motes: samba-server records and exports; samba-inspect reads the live take;
    samba-replay --out gives exactly the live poses; samba-replay --connect --speed max into a
    second server gives every frame."""
    d = take / "live"
    d.mkdir()
    os.symlink(take / "sim", d / "sim")
    port, http = free_port(), free_port()
    server_cmd = readme_command("samba-server --calibration calibration.toml --listen")
    server_cmd = sub(sub(sub(server_cmd, "tcp/0.0.0.0:7447", f"tcp/127.0.0.1:{port}"),
                         "127.0.0.1:8080", f"127.0.0.1:{http}"), "calibration.toml", "sim/calibration.toml")
    mote_cmd = readme_command("samba-mote --id cam0 --source file:")
    assert "?start=T" in readme_text(), "the README no longer says how to start file motes in step"
    procs: list[subprocess.Popen] = []
    try:
        log = d / "server.log"
        srv = subprocess.Popen(["bash", "-c", "exec " + server_cmd], cwd=d, env=_env(), stdin=subprocess.DEVNULL,
                               stdout=log.open("w"), stderr=subprocess.STDOUT)
        procs.append(srv)
        wait_for(log, "listening on", srv, 120)
        wait_for(log, f"127.0.0.1:{http}", srv, 30)
        with urllib.request.urlopen(f"http://127.0.0.1:{http}/", timeout=10) as resp:
            assert resp.status == 200 and b"<" in resp.read(200)
        start = time.time() + 4.0  # every mote starts its file at the same instant, like cameras
        motes = []
        for k in range(4):
            cmd = sub(sub(mote_cmd, "tcp/127.0.0.1:7447", f"tcp/127.0.0.1:{port}"), "cam0", f"cam{k}")
            cmd = re.sub(r"file:\S*/cam(\d)\.avi", lambda m: f"'file:sim/cam{m.group(1)}.avi?start={start:.3f}'", cmd)
            motes.append(subprocess.Popen(["bash", "-c", cmd], cwd=d, env=_env(), stdin=subprocess.DEVNULL,
                                          stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True))
        procs += motes
        outs = []
        for m in motes:
            out, _ = m.communicate(timeout=120)
            assert m.returncode == 0, f"{m.args} exited {m.returncode}:\n{out}"
            outs.append(out)
        time.sleep(1.0)
        rc = stop(srv, log)
    finally:
        for p in procs:
            if p.poll() is None:
                p.kill()
                p.wait(10)
    frames = len(load_npz(take / "sim" / "joints.npz")["t"])
    for out in outs:
        assert f"{frames} frames" in out and "source ended" in out, out
    live = load_npz(d / "joints.npz")
    n_live, n_solved = len(live["t"]), int(solved(live["joints"]).sum())
    text = log.read_text()
    summary = re.search(r"(\d+) frames, (\d+) solved(?:, (\d+) solves skipped)?", text)
    assert summary, text
    skipped = int(summary.group(3) or 0)
    print(f"live server: {n_live} poses from {frames} video frames, {n_solved} solved, {skipped} solves skipped")
    assert n_live >= 0.95 * frames and (int(summary.group(1)), int(summary.group(2))) == (n_live, n_solved), text
    # a 2-core machine running 4 motes beside the server may fall behind: the server then skips solves
    # (max_lag_ms) and says so; the frames it had time for are solved
    assert n_solved >= 0.5 * (n_live - skipped), text
    if n_solved >= 0.5 * n_live:
        assert rc == 0, text
    else:  # a take mostly without poses says so, with the reason and the way out, and exits 3
        assert rc == 3 and "WARNING: only" in text and "--solve-all" in text, text
        run(sub(readme_command("samba-replay take.mcap --out"), "joints.npz", "all.npz") + " --solve-all", d)
        assert solved(load_npz(d / "all.npz")["joints"]).sum() >= 0.5 * n_live

    # step 4: inspect the live take; replay it in-process: exactly the live poses
    r = run(readme_command("samba-inspect take.mcap --plot"), d)
    dur = float(re.search(r"take\.mcap: ([\d.e+]+) s", r.out).group(1))
    assert dur < 2 * frames / 60 + 5, f"duration {dur} s"
    lat = [float(x) for x in re.findall(r"latency p50 ([\d.e+-]+) ms", r.out)]
    assert lat and all(0 <= x < 1000 for x in lat), r.out
    run(sub(readme_command("samba-replay take.mcap --out"), "joints.npz", "replay.npz"), d)
    same_poses(d / "joints.npz", d / "replay.npz")

    # samba-replay --connect --speed max into a second live server (the same README command)
    d2 = d / "second"
    d2.mkdir()
    os.symlink(take / "sim", d2 / "sim")
    port2, http2 = free_port(), free_port()
    cmd2 = server_cmd.replace(f"127.0.0.1:{port}", f"127.0.0.1:{port2}").replace(f"127.0.0.1:{http}", f"127.0.0.1:{http2}")
    log2 = d2 / "server.log"
    srv2 = subprocess.Popen(["bash", "-c", "exec " + cmd2], cwd=d2, env=_env(), stdin=subprocess.DEVNULL,
                            stdout=log2.open("w"), stderr=subprocess.STDOUT)
    try:
        wait_for(log2, "listening on", srv2, 120)
        rep = sub(readme_command("samba-replay take.mcap --connect"), "tcp/127.0.0.1:7447", f"tcp/127.0.0.1:{port2}")
        run(sub(rep, "take.mcap", "../take.mcap"), d2, timeout=120)
        time.sleep(1.0)
        assert stop(srv2, log2) == 0, log2.read_text()
    finally:
        if srv2.poll() is None:
            srv2.kill()
            srv2.wait(10)
    again = load_npz(d2 / "joints.npz")
    assert len(again["t"]) == n_live, f"{len(again['t'])} poses from the replay, {n_live} live"
    assert solved(again["joints"]).sum() >= n_solved


def test_demo(tmp_path: Path) -> None:
    cmd = readme_command("samba-demo --duration")
    cmd = sub(re.sub(r"--duration \d+", "--duration 5", cmd), "--http 8080", f"--http {free_port()}")
    r = run(cmd, tmp_path, timeout=120)
    m = re.search(r"session (\S+) on (tcp/[\d.]+:\d+)", r.out)
    assert m, r.out
    done = re.search(r"(\d+) frames, (\d+) solved", r.out)
    assert done and int(done.group(2)) > 0, r.out
