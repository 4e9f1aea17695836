"""Command-line entry points of the server side, one module per command (``samba-NAME`` ->
``samba_server.cli.NAME``): db, reconstruct, server, process, replay, inspect, demo, export,
calibrate. Each holds only the argparse ``main()`` and its helpers; the work is done by the
library modules (:mod:`samba_server.app`, :mod:`samba_server.recon`, ...).
"""

from samba_common.quietpipe import install as _quiet_pipe

# A command piped into ``head`` ends quietly, as Unix tools do (samba_common.quietpipe: stdout
# only; SIGPIPE stays ignored, so a closed network socket never kills a server).
_quiet_pipe()
