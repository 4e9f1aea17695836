"""Command-line entry points of the mote side, one module per command: ``samba-mote``
(:mod:`.mote`), ``samba-sim`` (:mod:`.sim`), ``samba-gateway`` (:mod:`.gateway`).

Like the rest of samba_mote: no scipy, heavy imports inside ``main()``.
"""
