"""Command-line output that survives a reader leaving early (``samba-inspect take.mcap | head``).

Python ignores SIGPIPE, so a write into a closed pipe raises BrokenPipeError: a traceback for a
user who only wanted the first lines, or worse, a live server that dies because whoever read its
stdout went away. Restoring SIGPIPE's default action would kill the process on *any* closed
socket too (a network peer leaving), so instead stdout is wrapped: once its reader is gone, the
output goes to /dev/null and the command carries on (a server keeps recording) and exits with
its own exit code.
"""

from __future__ import annotations

import os
import sys

__all__ = ["install"]


class _PipeSafe:
    """A text stream whose writes into a closed pipe are dropped (fd redirected to /dev/null)."""

    def __init__(self, stream):
        self._stream = stream

    def write(self, text: str) -> int:
        try:
            return self._stream.write(text)
        except BrokenPipeError:
            self._drop()
            return len(text)

    def flush(self) -> None:
        try:
            self._stream.flush()
        except BrokenPipeError:
            self._drop()

    def _drop(self) -> None:
        try:
            fd = os.open(os.devnull, os.O_WRONLY)
            os.dup2(fd, self._stream.fileno())
            os.close(fd)
        except OSError:
            pass

    def __getattr__(self, name: str):
        return getattr(self._stream, name)


def install() -> None:
    """Wrap ``sys.stdout`` (a real file descriptor only; test captures are left alone). Idempotent."""
    out = sys.stdout
    if out is None or isinstance(out, _PipeSafe):
        return
    try:
        out.fileno()
    except (AttributeError, OSError, ValueError):
        return
    sys.stdout = _PipeSafe(out)
