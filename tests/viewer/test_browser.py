"""The page in a real headless Chromium: poses arrive (DOM counter) and it renders (screenshot).

Needs Debian's chromium (``apt-get install -y chromium``); skipped with that reason otherwise.
"""

from __future__ import annotations

import re
import shutil
import subprocess

import numpy as np
import pytest

from .conftest import Publisher

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
pytestmark = pytest.mark.skipif(CHROMIUM is None, reason="chromium not installed (apt-get install -y chromium)")


def chromium(tmp_path, url: str, *args: str, budget_ms: int = 3000) -> subprocess.CompletedProcess:
    profile = tmp_path / "chromium-profile"
    cmd = [CHROMIUM, "--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
           "--disable-component-update", "--disable-sync", "--no-first-run", f"--user-data-dir={profile}",
           "--window-size=1280,760", f"--virtual-time-budget={budget_ms}",
           "--enable-unsafe-swiftshader", "--use-angle=swiftshader", *args, url]
    return subprocess.run(cmd, capture_output=True, text=True, timeout=90)


def dump_dom(tmp_path, url: str, ready) -> subprocess.CompletedProcess:
    """The page's DOM after Chromium ran it for a virtual-time budget: 6, then 15, then 30 s
    until ``ready(dom)`` holds (virtual time runs ahead of the real-time stream on a loaded
    machine, and the budget can end before the websocket's first messages arrived)."""
    for attempt, budget in enumerate((6000, 15000, 30000)):
        proc = chromium(tmp_path / f"try{attempt}", url, "--dump-dom", budget_ms=budget)
        assert proc.returncode == 0, proc.stderr[-2000:]
        if ready(proc.stdout):
            break
    return proc


def test_poses_arrive_in_the_page(tmp_path, viewer):
    with Publisher(viewer, seconds=90.0) as pub:
        # a stream of poses (not a count tied to the machine's speed) is what is checked
        proc = dump_dom(tmp_path, viewer.url, lambda dom: int(re.search(r'data-poses="(\d+)"', dom).group(1)) >= 5)
    body = re.search(r"<body[^>]*>", proc.stdout).group(0)
    poses = int(re.search(r'data-poses="(\d+)"', body).group(1))
    assert 'data-connected="1"' in body
    assert poses >= 5, f"only {poses} poses reached the page (published {pub.count})"
    assert re.search(r'id="pose-count">(\d+)<', proc.stdout).group(1) == str(poses)
    # status panel and one blob view per mote were filled in
    assert re.search(r'id="st-alive">1 / 2<', proc.stdout)
    assert re.search(r'data-mote="cam0"[^>]*data-blobs="8"', proc.stdout)
    assert 'data-mote="cam1"' in proc.stdout


def test_screenshot_shows_the_skeleton(tmp_path, viewer):
    import matplotlib.image as mpimg

    # headless Chromium now and then captures the page before the WebGL canvas is composited
    # (the HUD already shows the poses, the 3D view is blank, not even the floor grid), more
    # often on a loaded machine: up to 7 captures with longer budgets, the best counts (4 were
    # all blank once in a full .ci/run; alone the test needed 1-3; with
    # --run-all-compositor-stages-before-draw it needed 2-4)
    best = None
    with Publisher(viewer, seconds=180.0):
        for attempt, budget in enumerate((4000, 8000, 15000, 25000, 25000, 25000, 25000)):
            shot = tmp_path / f"viewer{attempt}.png"
            proc = chromium(tmp_path / f"try{attempt}", viewer.url, f"--screenshot={shot}", budget_ms=budget)
            assert proc.returncode == 0 and shot.exists(), proc.stderr[-2000:]
            img = mpimg.imread(shot)[..., :3]
            view = img[60:700, 300:600]  # the 3D view around the subject
            bright = (view.mean(axis=-1) > 0.6).sum()  # joints/bones on the dark background
            if best is None or bright > best[0]:
                best = (bright, img, view)
            if bright > 200:
                break
    bright, img, view = best
    assert img.shape[:2] == (760, 1280)
    assert bright > 200, "no skeleton drawn in the 3D view"
    orange = ((view[..., 0] > 0.5) & (view[..., 2] < 0.35) & (view[..., 1] > 0.25)).sum()
    assert orange > 20, "no markers drawn"
    assert np.std(img) > 0.05
