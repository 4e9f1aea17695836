"""Command-line entry points of the mote side, one module per command: ``samba-mote``
(:mod:`.mote`), ``samba-sim`` (:mod:`.sim`), ``samba-gateway`` (:mod:`.gateway`).

Like the rest of samba_mote: no scipy, heavy imports inside ``main()``.
"""

from samba_common.quietpipe import install as _quiet_pipe

# A command piped into ``head`` ends quietly, as Unix tools do (samba_common.quietpipe: stdout
# only; SIGPIPE stays ignored, so a closed network socket never kills a server).
_quiet_pipe()
