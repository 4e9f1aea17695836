"""Command-line entry points of the server side, one module per command (``samba-NAME`` ->
``samba_server.cli.NAME``): db, reconstruct, server, process, replay, inspect, demo, export,
calibrate. Each holds only the argparse ``main()`` and its helpers; the work is done by the
library modules (:mod:`samba_server.app`, :mod:`samba_server.recon`, ...).
"""
