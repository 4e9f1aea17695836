"""Who may talk to the server: mutual TLS and access control over real Zenoh sessions on loopback.

The "server" of most tests is a Zenoh session opened with exactly the settings samba-server
uses with ``--tls`` (:func:`samba_common.keys.server_settings`), with the server's subscribers,
liveliness subscriber and calibration queryable. Every "must not arrive" check is paired with a
legitimate message sent after it on another or the same link, so a pass is not a short wait.
The last test runs the real LiveServer with simulated motes over TLS and checks it solves.
"""

from __future__ import annotations

import stat
import threading
import time

import numpy as np
import pytest

from samba_common import keys
from samba_common import zenoh_util as zk

from .conftest import free_endpoint, overloaded, short_take

zenoh = pytest.importorskip("zenoh")
x509 = pytest.importorskip("cryptography.x509")

S = "sec"


@pytest.fixture(scope="module")
def keydirs(tmp_path_factory):
    """The session's keys (motes cam0..cam3, client 'viewer') and a stranger's keys with the same names."""
    root = tmp_path_factory.mktemp("keys")
    keys.init_keys(root / "session", motes=["cam0", "cam1", "cam2", "cam3"], clients=["viewer"])
    keys.init_keys(root / "stranger", motes=["cam0"], clients=["viewer"])
    return root / "session", root / "stranger"


def tls_endpoint() -> str:
    return "tls/" + free_endpoint().split("/", 1)[1]


class FakeServer:
    """A Zenoh session with samba-server's --tls settings and its declarations, recording what
    reaches it: marker/status samples, liveliness events."""

    def __init__(self, folder, endpoint: str):
        self.got: list[tuple[str, bytes]] = []
        self.live: list[str] = []
        self.lock = threading.Lock()
        self.z = zenoh.open(zk.make_config(listen=[endpoint], extra=keys.server_settings(folder, S)))
        self.decls = [
            self.z.declare_subscriber(f"samba/{S}/mote/*/markers", self._on),
            self.z.declare_subscriber(f"samba/{S}/mote/*/status", self._on),
            self.z.declare_subscriber(zk.pose_key(S), self._on),
            self.z.liveliness().declare_subscriber(zk.liveliness_key(S, "*"), self._on_live, history=True),
            self.z.declare_queryable(zk.calibration_key(S), lambda q: q.reply(q.key_expr, b"CALIBRATION")),
        ]
        self.pose_pub = self.z.declare_publisher(zk.pose_key(S))

    def _on(self, sample) -> None:
        with self.lock:
            self.got.append((str(sample.key_expr), sample.payload.to_bytes()))

    def _on_live(self, sample) -> None:
        with self.lock:
            self.live.append(str(sample.key_expr))

    def keys_got(self) -> list[str]:
        with self.lock:
            return [k for k, _ in self.got]

    def wait_for(self, payload: bytes, timeout: float = 5.0) -> bool:
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            with self.lock:
                if any(p == payload for _, p in self.got):
                    return True
            time.sleep(0.01)
        return False

    def wait_for_key(self, key: str, timeout: float = 5.0) -> bool:
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            if key in self.keys_got():
                return True
            time.sleep(0.01)
        return False

    def close(self) -> None:
        self.z.close()


@pytest.fixture
def server(keydirs):
    ep = tls_endpoint()
    srv = FakeServer(keydirs[0], ep)
    srv.endpoint = ep
    yield srv
    srv.close()


def open_peer(endpoint: str, extra: dict | None, mode: str = "peer"):
    return zenoh.open(zk.make_config(mode=mode, connect=[endpoint], extra=extra))


def legit_mote(server, folder, mote="cam3"):
    """A real mote session; returns (session, publisher) once the server's subscriber matched it."""
    z = open_peer(server.endpoint, keys.mote_settings(folder, mote))
    pub = z.declare_publisher(zk.markers_key(S, mote))
    end = time.monotonic() + 5
    while not pub.matching_status.matching and time.monotonic() < end:
        time.sleep(0.01)
    assert pub.matching_status.matching, "a mote with the session's certificate did not reach the server"
    return z, pub


# ---------------------------------------------------------------------------- the keys
def test_keys_layout_permissions_and_usages(keydirs, tmp_path):
    d = keydirs[0]
    for rel in ("ca.crt", "ca.key", "server.crt", "server.key", "motes/cam0.crt", "motes/cam0.key",
                "clients/viewer.crt", "clients/viewer.key"):
        assert (d / rel).is_file(), rel
    for key in [d / "ca.key", d / "server.key", *d.glob("motes/*.key")]:
        assert stat.S_IMODE(key.stat().st_mode) == 0o600, key
    from cryptography.x509.oid import ExtendedKeyUsageOID, NameOID

    def info(p):
        c = x509.load_pem_x509_certificate(p.read_bytes())
        cn = c.subject.get_attributes_for_oid(NameOID.COMMON_NAME)[0].value
        return cn, set(c.extensions.get_extension_for_class(x509.ExtendedKeyUsage).value), c
    cn, eku, srv = info(d / "server.crt")
    assert cn == keys.SERVER_CN and ExtendedKeyUsageOID.SERVER_AUTH in eku
    cn, eku, mote = info(d / "motes/cam0.crt")
    assert cn == "samba-mote-cam0" and eku == {ExtendedKeyUsageOID.CLIENT_AUTH}
    ca = x509.load_pem_x509_certificate((d / "ca.crt").read_bytes())
    mote.verify_directly_issued_by(ca)
    with pytest.raises(keys.KeysError, match="already exists"):
        keys.init_keys(d)
    with pytest.raises(keys.KeysError, match="ca.crt"):
        keys.add_mote(tmp_path / "nowhere", "cam0")
    acl = keys.access_control(S, ["cam0"], [])
    assert acl["default_permission"] == "deny" and acl["enabled"] is True


# ---------------------------------------------------------------------------- strangers
@pytest.mark.parametrize("who", ["plain tcp", "tls without certificate", "another CA's cam0"])
def test_a_stranger_cannot_publish_or_subscribe(server, keydirs, who):
    session_dir, stranger_dir = keydirs
    ca_only = {"transport/link/tls/root_ca_certificate": str(session_dir / "ca.crt")}
    if who == "plain tcp":
        endpoint, extra = "tcp/" + server.endpoint.split("/", 1)[1], None
    elif who == "tls without certificate":
        endpoint, extra = server.endpoint, ca_only
    else:
        endpoint, extra = server.endpoint, keys.mote_settings(stranger_dir, "cam0")
    # client mode: opening fails outright
    with pytest.raises(Exception, match="(?i)connect"):
        open_peer(endpoint, extra, mode="client")
    # peer mode opens (it would retry in the background) but nothing passes either way
    z = open_peer(endpoint, extra)
    try:
        poses: list = []
        z.declare_subscriber(zk.pose_key(S), lambda s: poses.append(s.payload.to_bytes()))
        z.liveliness().declare_token(zk.liveliness_key(S, "cam0"))
        time.sleep(0.3)
        z.put(zk.markers_key(S, "cam0"), b"stranger")
        z.put(zk.pose_key(S), b"stranger")
        assert [r for r in z.get(zk.calibration_key(S), timeout=1.0) if r.ok is not None] == []
        legit, pub = legit_mote(server, session_dir)
        try:
            pub.put(b"legit")
            assert server.wait_for(b"legit")
            for _ in range(10):  # half a second of poses: a subscription that got through would see them
                server.pose_pub.put(b"server pose")
                time.sleep(0.05)
        finally:
            legit.close()
        assert b"stranger" not in [p for _, p in server.got]
        assert zk.liveliness_key(S, "cam0") not in server.live
        assert b"server pose" not in poses  # (its own put is delivered locally; the server's never)
    finally:
        z.close()


def test_a_mote_certificate_cannot_pose_as_the_server(keydirs):
    """Only the server's certificate carries serverAuth: a stolen mote key cannot run a fake server."""
    d = keydirs[0]
    ep = tls_endpoint()
    fake = zenoh.open(zk.make_config(listen=[ep], extra=keys.tls_settings(d, keys.mote_identity(d, "cam0"), True)))
    try:
        with pytest.raises(Exception, match="(?i)connect"):
            open_peer(ep, keys.mote_settings(d, "cam1"), mode="client")
    finally:
        fake.close()


# ---------------------------------------------------------------------------- the session's own
def test_a_mote_publishes_only_under_its_own_name(server, keydirs):
    d = keydirs[0]
    z = open_peer(server.endpoint, keys.mote_settings(d, "cam0"))
    try:
        poses: list = []
        z.declare_subscriber(zk.pose_key(S), lambda s: poses.append(s.payload.to_bytes()))
        z.liveliness().declare_token(zk.liveliness_key(S, "cam1"))  # someone else's token
        z.declare_queryable(zk.calibration_key(S), lambda q: q.reply(q.key_expr, b"FAKE CALIBRATION"))
        own = z.declare_publisher(zk.markers_key(S, "cam0"))
        end = time.monotonic() + 5
        while not own.matching_status.matching and time.monotonic() < end:
            time.sleep(0.01)
        z.put(zk.markers_key(S, "cam1"), b"impersonated")
        z.put(zk.status_key(S, "cam2"), b"impersonated")
        z.put(zk.pose_key(S), b"forged pose")
        z.liveliness().declare_token(zk.liveliness_key(S, "cam0"))
        own.put(b"own")
        assert server.wait_for(b"own")
        for _ in range(10):
            server.pose_pub.put(b"server pose")
            time.sleep(0.05)
        got = server.keys_got()
        assert zk.markers_key(S, "cam1") not in got and zk.status_key(S, "cam2") not in got
        assert b"forged pose" not in [p for _, p in server.got]
        assert zk.liveliness_key(S, "cam1") not in server.live and zk.liveliness_key(S, "cam0") in server.live
        assert b"server pose" not in poses  # motes may not read the poses
        # the calibration comes from the server only, even with a mote's fake queryable around
        with open_peer(server.endpoint, keys.client_settings(d, "viewer")) as reader:
            answers = [r.ok.payload.to_bytes() for r in reader.get(zk.calibration_key(S), timeout=2.0)
                       if r.ok is not None]
        assert answers == [b"CALIBRATION"]
    finally:
        z.close()


def test_a_client_reads_poses_but_publishes_nothing(server, keydirs):
    d = keydirs[0]
    with open_peer(server.endpoint, keys.client_settings(d, "viewer")) as z:
        poses: list = []
        sub_pub = z.declare_publisher(zk.markers_key(S, "cam0"))
        z.declare_subscriber(zk.pose_key(S), lambda s: poses.append(s.payload.to_bytes()))
        sub_pub.put(b"client as cam0")
        end = time.monotonic() + 5  # until the subscription has reached the server
        while b"server pose" not in poses and time.monotonic() < end:
            server.pose_pub.put(b"server pose")
            time.sleep(0.05)
        assert b"server pose" in poses
        assert [r.ok.payload.to_bytes() for r in z.get(zk.calibration_key(S), timeout=2.0) if r.ok] == [b"CALIBRATION"]
        legit, pub = legit_mote(server, d)
        try:
            pub.put(b"legit")
            assert server.wait_for(b"legit")
        finally:
            legit.close()
        assert b"client as cam0" not in [p for _, p in server.got]


# ---------------------------------------------------------------------------- the real server
def test_live_server_solves_over_tls(keydirs):
    from samba_common.calib import default_rig
    from samba_common.pose_wire import decode_pose
    from samba_server.live import LiveServer
    from samba_server.recon import Reconstructor
    from samba_server.server import Server
    from samba_server.simmotes import SimMotes

    d = keydirs[0]
    ep = tls_endpoint()
    joints, _t = short_take()
    rig = default_rig(4)
    server = Server(rig, reconstructor=Reconstructor())
    received: list = []
    with LiveServer(server, session=S, listen=[ep], extra=keys.server_settings(d, S)):
        with open_peer(ep, keys.client_settings(d, "viewer")) as reader:
            reader.declare_subscriber(zk.pose_key(S), lambda s: received.append(s.payload.to_bytes()))
            encodings: set = set()
            reader.declare_subscriber(zk.pose_json_key(S), lambda s: encodings.add(str(s.encoding)))
            with SimMotes(rig, joints, 60.0, S, [ep], tls=str(d)) as sim:
                assert sim.open_all(timeout=10), "TLS motes did not match the server"
                sim.start()
                assert sim.done.wait(len(joints) / 60.0 + 10)
                time.sleep(0.5)
    poses = [decode_pose(b) for b in received]
    solved = [p for p in poses if p.solved]
    assert server.stats.packets >= 0.9 * 4 * len(joints)
    # on an overloaded machine late packets leave frames incomplete and unsolved (59-95 of 132
    # solved beside two benchmarks on 2 cores): the share is checked only while it is not
    if not overloaded():
        assert len(solved) >= 0.8 * len(joints), f"{len(solved)} solved of {len(joints)} frames over TLS"
    assert server.stats.bad_packets == 0 and server.stats.unknown_motes == 0
    assert np.isfinite(solved[-1].joints).all()
    assert encodings == {"application/json"}  # the JSON poses say what they are


def test_mote_cli_over_tls(server, keydirs, tmp_path):
    """samba-mote --tls: the real command publishes through mutual TLS; a mote without its
    certificate or with a tcp/ endpoint exits before capturing."""
    from samba_mote.cli.mote import main as mote_main
    from samba_mote.sim import SimConfig, make_take

    d = keydirs[0]
    take = make_take(tmp_path / "take", None, rig=2, seconds=0.5, seed=1,
                     config=SimConfig(tpose_stance="apart", pose_at=None))
    calib = tmp_path / "calibration.toml"
    take.rig.save(calib)
    src = f"file:{take.video('cam0')}?realtime=1"
    assert mote_main(["--id", "cam0", "--source", src, "--calibration", str(calib), "--session", S,
                      "--tls", str(d), "--connect", server.endpoint, "--max-frames", "60"]) == 0
    assert server.wait_for_key(zk.markers_key(S, "cam0"))
    assert mote_main(["--id", "cam9", "--source", src, "--tls", str(d), "--connect", server.endpoint]) == 1
    assert mote_main(["--id", "cam0", "--source", src, "--tls", str(d),
                      "--connect", "tcp/" + server.endpoint.split("/", 1)[1]]) == 2


def test_samba_keys_cli(tmp_path, capsys):
    from samba_server.cli.keys import main

    d = tmp_path / "keys"
    assert main(["init", str(d), "--motes", "2", "--clients", "laptop"]) == 0
    assert "cam0, cam1" in capsys.readouterr().out
    assert sorted(keys.list_names(d, "motes")) == ["cam0", "cam1"] and keys.list_names(d, "clients") == ["laptop"]
    assert main(["init", str(d)]) == 1 and "already exists" in capsys.readouterr().err
    assert main(["add-mote", str(d), "--id", "cam7"]) == 0 and (d / "motes" / "cam7.key").is_file()
    assert main(["add-mote", str(tmp_path / "none"), "--id", "cam7"]) == 1
    assert "ca.crt" in capsys.readouterr().err
    with pytest.raises(SystemExit) as exc:
        main(["add-mote", str(d), "--id", "../evil"])
    assert exc.value.code == 2
    assert main(["show", str(d), "--session", "lab"]) == 0
    out = capsys.readouterr().out
    assert "samba/lab/mote/cam7/**" in out and "samba-client-laptop" in out
