"""Session keys: a session CA, per-mote / server / client certificates, and the Zenoh settings
(mutual TLS and access control) that use them.

Nothing here is home-made cryptography: keys and X.509 certificates come from the
``cryptography`` package (ECDSA P-256, SHA-256), and the TLS handshake, certificate checks and
message filtering are Zenoh's own (``transport/link/tls`` and ``access_control``).

Layout of a keys folder (``samba-keys init DIR``)::

    DIR/ca.crt                  session CA certificate: every machine of the session needs it
    DIR/ca.key                  CA private key: stays on the machine that runs samba-keys
    DIR/server.crt, server.key  the server          (CN "samba-server",      serverAuth + clientAuth)
    DIR/motes/{id}.crt, .key    one per mote        (CN "samba-mote-{id}",   clientAuth)
    DIR/clients/{name}.crt,.key pose readers        (CN "samba-client-{name}", clientAuth)

A mote only needs ``ca.crt`` and its own ``motes/{id}.*`` (same layout). The access-control
rules are not stored: the server builds them at start from the certificates it finds in the
folder and the session it runs (:func:`access_control`), so adding a mote is one command and a
server restart.
"""

from __future__ import annotations

import datetime as _dt
import ipaddress
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from . import zenoh_util as zk

SERVER_CN = "samba-server"
MOTE_CN_PREFIX = "samba-mote-"
CLIENT_CN_PREFIX = "samba-client-"
VALID_DAYS = 3650


class KeysError(OSError):
    """A keys folder is missing, incomplete or does not belong together."""


@dataclass(frozen=True)
class Identity:
    """One certificate + key pair, as file paths."""

    cert: Path
    key: Path


def _crypto():
    try:
        from cryptography import x509
        from cryptography.hazmat.primitives import hashes, serialization
        from cryptography.hazmat.primitives.asymmetric import ec
        from cryptography.x509.oid import ExtendedKeyUsageOID, NameOID
    except ImportError as exc:  # pragma: no cover - a declared dependency
        raise KeysError("the 'cryptography' package is needed for samba-keys (pip install cryptography)") from exc
    return x509, hashes, serialization, ec, ExtendedKeyUsageOID, NameOID


def _write_private(path: Path, data: bytes) -> None:
    """Write a private key readable by its owner only (0600)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
    with os.fdopen(fd, "wb") as fh:
        fh.write(data)
    os.chmod(path, 0o600)


def _new_key():
    _x, _h, _s, ec, _e, _n = _crypto()
    return ec.generate_private_key(ec.SECP256R1())


def _key_pem(key) -> bytes:
    _x, _h, serialization, _e, _eku, _n = _crypto()
    return key.private_bytes(serialization.Encoding.PEM, serialization.PrivateFormat.PKCS8,
                             serialization.NoEncryption())


def _load_ca(folder: Path):
    x509, _h, serialization, _e, _eku, _n = _crypto()
    cert_p, key_p = folder / "ca.crt", folder / "ca.key"
    for p in (cert_p, key_p):
        if not p.is_file():
            raise KeysError(f"{p}: missing (create the folder with 'samba-keys init {folder}')")
    try:
        cert = x509.load_pem_x509_certificate(cert_p.read_bytes())
        key = serialization.load_pem_private_key(key_p.read_bytes(), password=None)
    except ValueError as exc:
        raise KeysError(f"{cert_p} / {key_p}: not a PEM certificate and key ({exc})") from None
    return cert, key


def _issue(folder: Path, ca_cert, ca_key, cn: str, out: Identity, server: bool,
           hosts: tuple[str, ...] = ()) -> Identity:
    """Sign a new key for ``cn`` with the CA and write it to ``out``."""
    x509, hashes, serialization, _ec, EKU, NameOID = _crypto()
    key = _new_key()
    now = _dt.datetime.now(_dt.timezone.utc)
    sans: list = []
    for h in hosts:
        try:
            sans.append(x509.IPAddress(ipaddress.ip_address(h)))
        except ValueError:
            sans.append(x509.DNSName(h))
    usages = [EKU.CLIENT_AUTH] + ([EKU.SERVER_AUTH] if server else [])
    builder = (x509.CertificateBuilder()
               .subject_name(x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, cn)]))
               .issuer_name(ca_cert.subject)
               .public_key(key.public_key())
               .serial_number(x509.random_serial_number())
               .not_valid_before(now - _dt.timedelta(minutes=5))
               .not_valid_after(now + _dt.timedelta(days=VALID_DAYS))
               .add_extension(x509.BasicConstraints(ca=False, path_length=None), critical=True)
               .add_extension(x509.KeyUsage(digital_signature=True, content_commitment=False, key_encipherment=False,
                                            data_encipherment=False, key_agreement=False, key_cert_sign=False,
                                            crl_sign=False, encipher_only=False, decipher_only=False), critical=True)
               .add_extension(x509.ExtendedKeyUsage(usages), critical=False)
               .add_extension(x509.AuthorityKeyIdentifier.from_issuer_public_key(ca_key.public_key()), critical=False)
               .add_extension(x509.SubjectKeyIdentifier.from_public_key(key.public_key()), critical=False))
    if sans:
        builder = builder.add_extension(x509.SubjectAlternativeName(sans), critical=False)
    cert = builder.sign(ca_key, hashes.SHA256())
    _write_private(out.key, _key_pem(key))
    out.cert.parent.mkdir(parents=True, exist_ok=True)
    out.cert.write_bytes(cert.public_bytes(serialization.Encoding.PEM))
    return out


def mote_identity(folder: str | os.PathLike, mote_id: str) -> Identity:
    """Paths of mote ``mote_id``'s certificate and key in ``folder`` (not checked)."""
    zk.mote_prefix("x", mote_id)  # validates the id
    d = Path(folder) / "motes"
    return Identity(d / f"{mote_id}.crt", d / f"{mote_id}.key")


def client_identity(folder: str | os.PathLike, name: str) -> Identity:
    """Paths of client ``name``'s certificate and key in ``folder`` (not checked)."""
    zk.mote_prefix("x", name)
    d = Path(folder) / "clients"
    return Identity(d / f"{name}.crt", d / f"{name}.key")


def server_identity(folder: str | os.PathLike) -> Identity:
    """Paths of the server's certificate and key in ``folder`` (not checked)."""
    return Identity(Path(folder) / "server.crt", Path(folder) / "server.key")


def init_keys(folder: str | os.PathLike, motes: list[str] = (), clients: list[str] = (),
              hosts: tuple[str, ...] = (), force: bool = False) -> list[Path]:
    """Create a session CA, the server's certificate and one per mote / client in ``folder``.

    hosts: extra DNS names / IP addresses of the server put in its certificate (loopback is
    always there). Refuses to overwrite an existing CA unless ``force``. Returns the files written.
    """
    x509, hashes, serialization, _ec, _eku, NameOID = _crypto()
    folder = Path(folder)
    if (folder / "ca.key").exists() and not force:
        raise KeysError(f"{folder / 'ca.key'}: a session CA already exists (add motes with "
                        f"'samba-keys add-mote {folder} --id ID', or use --force to start over)")
    for m in motes:
        zk.mote_prefix("x", m)
    for c in clients:
        zk.mote_prefix("x", c)
    folder.mkdir(parents=True, exist_ok=True)
    ca_key = _new_key()
    now = _dt.datetime.now(_dt.timezone.utc)
    name = x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, f"samba session CA {now:%Y-%m-%d %H:%M}")])
    ca = (x509.CertificateBuilder().subject_name(name).issuer_name(name).public_key(ca_key.public_key())
          .serial_number(x509.random_serial_number())
          .not_valid_before(now - _dt.timedelta(minutes=5)).not_valid_after(now + _dt.timedelta(days=VALID_DAYS))
          .add_extension(x509.BasicConstraints(ca=True, path_length=0), critical=True)
          .add_extension(x509.KeyUsage(digital_signature=False, content_commitment=False, key_encipherment=False,
                                       data_encipherment=False, key_agreement=False, key_cert_sign=True,
                                       crl_sign=True, encipher_only=False, decipher_only=False), critical=True)
          .add_extension(x509.SubjectKeyIdentifier.from_public_key(ca_key.public_key()), critical=False)
          .sign(ca_key, hashes.SHA256()))
    _write_private(folder / "ca.key", _key_pem(ca_key))
    (folder / "ca.crt").write_bytes(ca.public_bytes(serialization.Encoding.PEM))
    written = [folder / "ca.crt", folder / "ca.key"]
    all_hosts = tuple(dict.fromkeys(("localhost", "127.0.0.1", "::1", *hosts)))
    srv = _issue(folder, ca, ca_key, SERVER_CN, server_identity(folder), server=True, hosts=all_hosts)
    written += [srv.cert, srv.key]
    for m in motes:
        written += list(_astuple(add_mote(folder, m)))
    for c in clients:
        written += list(_astuple(add_client(folder, c)))
    return written


def _astuple(ident: Identity) -> tuple[Path, Path]:
    return ident.cert, ident.key


def add_mote(folder: str | os.PathLike, mote_id: str) -> Identity:
    """Issue (or re-issue) mote ``mote_id``'s certificate, signed by the folder's CA."""
    ca, key = _load_ca(Path(folder))
    return _issue(Path(folder), ca, key, MOTE_CN_PREFIX + mote_id, mote_identity(folder, mote_id), server=False)


def add_client(folder: str | os.PathLike, name: str) -> Identity:
    """Issue a read-only client certificate (poses, statuses, calibration) named ``name``."""
    ca, key = _load_ca(Path(folder))
    return _issue(Path(folder), ca, key, CLIENT_CN_PREFIX + name, client_identity(folder, name), server=False)


def list_names(folder: str | os.PathLike, kind: str) -> list[str]:
    """Ids of the motes (kind "motes") or clients (kind "clients") with a certificate in ``folder``."""
    d = Path(folder) / kind
    return sorted(p.stem for p in d.glob("*.crt")) if d.is_dir() else []


def _require(*paths: Path) -> None:
    for p in paths:
        if not p.is_file():
            raise KeysError(f"{p}: missing (see 'samba-keys --help')")


def tls_settings(folder: str | os.PathLike, identity: Identity, listen: bool) -> dict[str, Any]:
    """Zenoh ``transport/link/tls`` settings for mutual TLS with ``identity``.

    The same certificate is presented when listening and when connecting; peers must present
    a certificate signed by the session CA (``enable_mtls``). Host names are not checked on
    connect (the server's address is not known when the keys are made); instead only the server
    certificate carries the serverAuth usage, so a mote's or client's certificate cannot pose as
    the server.
    """
    ca = Path(folder) / "ca.crt"
    _require(ca, identity.cert, identity.key)
    s = {"transport/link/tls/root_ca_certificate": str(ca),
         "transport/link/tls/enable_mtls": True,
         "transport/link/tls/verify_name_on_connect": False,
         "transport/link/tls/connect_certificate": str(identity.cert),
         "transport/link/tls/connect_private_key": str(identity.key)}
    if listen:
        s["transport/link/tls/listen_certificate"] = str(identity.cert)
        s["transport/link/tls/listen_private_key"] = str(identity.key)
    return s


def access_control(session: str, motes: list[str], clients: list[str] = ()) -> dict[str, Any]:
    """The server's Zenoh ``access_control`` config for ``session``.

    Default deny. Ingress (what others may send to the server):

    - mote ``{id}`` (certificate CN ``samba-mote-{id}``): put and liveliness token under
      ``samba/{session}/mote/{id}/**`` only; query ``samba/{session}/calibration``;
    - clients (CN ``samba-client-{name}``): subscribe to poses and mote statuses, watch mote
      liveliness, query the calibration; they publish nothing;
    - nobody else publishes poses or declares a calibration queryable: the server is the only
      source of both.

    Egress (what the server sends): everything under ``samba/{session}/**`` to the session's
    certificates (its subscriptions, its replies, its poses to subscribed clients).
    """
    s = zk.calibration_key(session).rsplit("/", 1)[0]  # samba/{session}, validated
    mote_cns = {m: MOTE_CN_PREFIX + m for m in motes}
    client_cns = [CLIENT_CN_PREFIX + c for c in clients]
    all_cns = [SERVER_CN, *mote_cns.values(), *client_cns]
    rules: list[dict] = [
        {"id": "egress", "permission": "allow", "flows": ["egress"],
         "messages": ["put", "delete", "declare_subscriber", "declare_queryable", "query", "reply",
                      "liveliness_token", "liveliness_query", "declare_liveliness_subscriber"],
         "key_exprs": [f"{s}/**"]},
        {"id": "ask-calibration", "permission": "allow", "flows": ["ingress"], "messages": ["query"],
         "key_exprs": [zk.calibration_key(session)]},
        {"id": "read", "permission": "allow", "flows": ["ingress"],
         "messages": ["declare_subscriber", "declare_liveliness_subscriber", "liveliness_query"],
         "key_exprs": [zk.pose_key(session), zk.pose_json_key(session), zk.status_key(session, "*"),
                       zk.liveliness_key(session, "*")]},
    ]
    subjects: list[dict] = [{"id": "session", "cert_common_names": all_cns}]
    policies: list[dict] = [{"id": "session-egress", "rules": ["egress"], "subjects": ["session"]},
                            {"id": "session-calibration", "rules": ["ask-calibration"], "subjects": ["session"]}]
    if client_cns:
        subjects.append({"id": "clients", "cert_common_names": client_cns})
        policies.append({"id": "clients-read", "rules": ["read"], "subjects": ["clients"]})
    for m, cn in mote_cns.items():
        rules.append({"id": f"mote-{m}", "permission": "allow", "flows": ["ingress"],
                      "messages": ["put", "delete", "liveliness_token"],
                      "key_exprs": [f"{zk.mote_prefix(session, m)}/**"]})
        subjects.append({"id": f"mote-{m}", "cert_common_names": [cn]})
        policies.append({"id": f"mote-{m}", "rules": [f"mote-{m}"], "subjects": [f"mote-{m}"]})
    return {"enabled": True, "default_permission": "deny", "rules": rules, "subjects": subjects,
            "policies": policies}


def server_settings(folder: str | os.PathLike, session: str) -> dict[str, Any]:
    """Zenoh settings of the server: mutual TLS as ``samba-server`` plus :func:`access_control`
    for the motes and clients whose certificates are in ``folder``."""
    s = tls_settings(folder, server_identity(folder), listen=True)
    s["access_control"] = access_control(session, list_names(folder, "motes"), list_names(folder, "clients"))
    return s


def mote_settings(folder: str | os.PathLike, mote_id: str) -> dict[str, Any]:
    """Zenoh settings of mote ``mote_id`` (mutual TLS with its own certificate)."""
    ident = mote_identity(folder, mote_id)
    if not ident.cert.is_file() and (Path(folder) / "ca.crt").is_file():
        raise KeysError(f"{ident.cert}: no certificate for mote {mote_id} "
                        f"(make one with 'samba-keys add-mote {folder} --id {mote_id}')")
    return tls_settings(folder, ident, listen=False)


def client_settings(folder: str | os.PathLike, name: str) -> dict[str, Any]:
    """Zenoh settings of a read-only client ``name``."""
    return tls_settings(folder, client_identity(folder, name), listen=False)


def check_endpoints(endpoints: list[str], what: str) -> None:
    """With --tls every endpoint must be ``tls/HOST:PORT``; raise ValueError naming the bad one."""
    for ep in endpoints:
        if not str(ep).startswith("tls/"):
            raise ValueError(f"{what} {ep!r}: with --tls use a tls/HOST:PORT endpoint (e.g. tls/127.0.0.1:7447)")
