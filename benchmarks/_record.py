"""Write a benchmark's figures into docs/BENCHMARKS.md (one section per benchmark, replaced on rerun)."""

from __future__ import annotations

import datetime
import os
import platform
import re
from pathlib import Path

DOC = Path(__file__).resolve().parents[1] / "docs" / "BENCHMARKS.md"


def machine() -> str:
    """One line naming the machine: CPU model, cores, Python."""
    cpu = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return f"{cpu}, {os.cpu_count()} cores, {platform.system()} {platform.release()}, Python {platform.python_version()}"


def _section(title: str) -> re.Pattern:
    """The pattern of the section ``## title`` (heading included, up to the next section)."""
    return re.compile(rf"^## {re.escape(title)}\n.*?(?=^## |\Z)", re.S | re.M)


def recorded(title: str) -> str | None:
    """The recorded section ``## title`` of docs/BENCHMARKS.md (heading included), or None."""
    m = _section(title).search(DOC.read_text()) if DOC.exists() else None
    return m.group(0) if m else None


def record(title: str, lines: list[str]) -> None:
    """Replace (or append) the section ``## title`` of docs/BENCHMARKS.md with ``lines``."""
    stamp = f"_Measured {datetime.date.today().isoformat()} on {machine()}._"
    body = f"## {title}\n\n{stamp}\n\n" + "\n".join(lines).rstrip() + "\n"
    text = DOC.read_text() if DOC.exists() else "# Benchmarks\n\nFigures written by the scripts in `benchmarks/`.\n"
    pattern = _section(title)
    text = pattern.sub(lambda _m: body + "\n", text) if pattern.search(text) else text.rstrip() + "\n\n" + body
    DOC.parent.mkdir(parents=True, exist_ok=True)
    DOC.write_text(text)
