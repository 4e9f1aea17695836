"""A command whose reader leaves early (``| head``) ends quietly, and importing the CLIs never
makes SIGPIPE fatal (a network peer closing a socket must not kill a server)."""

import signal
import subprocess
import sys

import pytest

SCRIPT = """
import signal, sys
import samba_server.cli, samba_mote.cli
assert signal.getsignal(signal.SIGPIPE) == signal.SIG_IGN, signal.getsignal(signal.SIGPIPE)
for _ in range(100000):
    print("x" * 100)
print("still running", file=sys.stderr)
"""


@pytest.mark.skipif(not hasattr(signal, "SIGPIPE"), reason="no SIGPIPE on this platform")
def test_output_into_a_closed_pipe_is_dropped_quietly():
    proc = subprocess.Popen([sys.executable, "-c", SCRIPT], stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    proc.stdout.read(10)
    proc.stdout.close()  # the reader leaves, like `head -c 10`
    err = proc.stderr.read().decode()
    assert proc.wait(timeout=60) == 0, err
    assert err.strip() == "still running"  # no traceback, and the command carried on
