"""A site CA and one certificate per peer, for Zenoh's mutual TLS.

Made with the ``cryptography`` package (no ``openssl`` command line to parse, and the
same code reads a certificate back to check its dates in ``check-config``). Keys are
ECDSA P-256 in PKCS#8 PEM (what rustls, inside Zenoh, reads), written owner-only
(0600) whatever the umask. A certificate says who it is in its subject: the common
name is the peer's NAME (for a shovel: its ``shovel.id``), the organizational unit its
role; both are what the routers' access-control lists are built from.
"""

from __future__ import annotations

import datetime as dt
import ipaddress
import os
import re
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from cryptography import x509
from cryptography.hazmat.primitives import hashes, serialization
from cryptography.hazmat.primitives.asymmetric import ec
from cryptography.x509.oid import ExtendedKeyUsageOID, NameOID

from shoveld import keys

ROLES = ("shovel", "cab", "office", "maintenance", "router")
"""Who a certificate is for; the router's access control grants by role."""


DEFAULT_HOSTS = ("localhost", "127.0.0.1", "::1")
CA_CERT = "ca.crt"
CA_KEY = "ca.key"


class PkiError(ValueError):
    """A PKI operation that cannot be done; the message names the file or name."""


@dataclass(frozen=True)
class CertInfo:
    """What a certificate says about its holder (read back from the PEM file)."""

    path: Path
    common_name: str
    role: str | None
    not_before: dt.datetime
    not_after: dt.datetime
    hosts: tuple[str, ...]


def _now() -> dt.datetime:
    return dt.datetime.now(dt.UTC)


def _write_private(path: Path, data: bytes) -> None:
    """Create ``path`` readable by its owner only (0600), refusing to overwrite."""
    try:
        fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
    except FileExistsError:
        raise PkiError(f"{path}: exists already (remove it to make a new one)") from None
    except OSError as e:
        raise PkiError(f"{path}: cannot write: {e.strerror}") from None
    with os.fdopen(fd, "wb") as f:
        os.fchmod(f.fileno(), 0o600)
        f.write(data)


def _write_public(path: Path, data: bytes) -> None:
    if path.exists():
        raise PkiError(f"{path}: exists already (remove it to make a new one)")
    try:
        path.write_bytes(data)
        path.chmod(0o644)
    except OSError as e:
        raise PkiError(f"{path}: cannot write: {e.strerror}") from None


def _key_pem(key: ec.EllipticCurvePrivateKey) -> bytes:
    return key.private_bytes(serialization.Encoding.PEM, serialization.PrivateFormat.PKCS8,
                             serialization.NoEncryption())


def init_ca(directory: str | Path, site: str = "shoveld site", days: int = 3650) -> Path:
    """Make the site CA (``ca.crt``, ``ca.key`` 0600) in ``directory``; its path."""
    d = Path(directory)
    if not site.strip() or len(site) > 61 or not site.isprintable():
        # the CA's common name is "SITE CA", and X.509 holds at most 64 characters there
        raise PkiError(f"site {site!r}: expected a name of 1-61 printable characters")
    if not 0 < days <= 36500:
        raise PkiError(f"days must be > 0 and at most 36500, got {days}")
    try:
        d.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise PkiError(f"{d}: cannot make the folder: {e.strerror}") from None
    if (d / CA_KEY).exists() or (d / CA_CERT).exists():
        raise PkiError(f"{d / CA_CERT}: a site CA exists already in {d}")
    key = ec.generate_private_key(ec.SECP256R1())
    name = x509.Name([x509.NameAttribute(NameOID.ORGANIZATION_NAME, site),
                      x509.NameAttribute(NameOID.COMMON_NAME, f"{site} CA")])
    now = _now()
    cert = (x509.CertificateBuilder().subject_name(name).issuer_name(name)
            .public_key(key.public_key()).serial_number(x509.random_serial_number())
            .not_valid_before(now - dt.timedelta(minutes=5))
            .not_valid_after(now + dt.timedelta(days=days))
            .add_extension(x509.BasicConstraints(ca=True, path_length=0), critical=True)
            .add_extension(x509.KeyUsage(digital_signature=False, content_commitment=False,
                                         key_encipherment=False, data_encipherment=False,
                                         key_agreement=False, key_cert_sign=True,
                                         crl_sign=True, encipher_only=False,
                                         decipher_only=False), critical=True)
            .add_extension(x509.SubjectKeyIdentifier.from_public_key(key.public_key()),
                           critical=False)
            .sign(key, hashes.SHA256()))
    _write_private(d / CA_KEY, _key_pem(key))
    _write_public(d / CA_CERT, cert.public_bytes(serialization.Encoding.PEM))
    return d / CA_CERT


def _load_ca(d: Path) -> tuple[x509.Certificate, ec.EllipticCurvePrivateKey]:
    try:
        cert = x509.load_pem_x509_certificate((d / CA_CERT).read_bytes())
        key = serialization.load_pem_private_key((d / CA_KEY).read_bytes(), None)
    except FileNotFoundError as e:
        raise PkiError(f"{e.filename}: no site CA here (run 'shoveld pki init --dir {d}' "
                       "first)") from None
    except (OSError, ValueError) as e:
        raise PkiError(f"{d / CA_KEY}: cannot read the site CA: {e}") from None
    if not isinstance(key, ec.EllipticCurvePrivateKey):
        raise PkiError(f"{d / CA_KEY}: not an EC key made by 'shoveld pki init'")
    mode = key_mode(d / CA_KEY)
    if mode & 0o077:
        raise PkiError(f"{d / CA_KEY}: others may read or change the site CA's key (mode "
                       f"{mode:04o}), and whoever reads it can issue certificates for the "
                       "site: make it owner-only (chmod 600) and think whether to make a "
                       "new CA")
    return cert, key


def key_mode(path: str | Path) -> int:
    """The permission bits of a key file (0o600 as written here)."""
    return os.stat(path).st_mode & 0o777


def key_words(crt: Path) -> str:
    """What ``pki list`` says of the key beside a certificate: owner-only, open to others
    (to fix), or not here (given to its computer, as it should be)."""
    k = crt.with_suffix(".key")
    if not k.exists():
        return "key not here"
    mode = key_mode(k)
    if mode & 0o007:
        return f"key mode {mode:04o}: OTHER USERS MAY READ IT, chmod 600"
    return "key owner-only" if not mode & 0o077 else f"key mode {mode:04o}"


_LABEL_RE = re.compile(r"[A-Za-z0-9](?:[A-Za-z0-9-]{0,61}[A-Za-z0-9])?")


def _host_ok(h: str) -> bool:
    """An IP address, or a host name others can dial (RFC 1123: dot-separated labels of
    letters, digits and inner hyphens, each 1-63 characters, 253 in all)."""
    try:
        ipaddress.ip_address(h)
        return True
    except ValueError:
        pass
    return 0 < len(h) <= 253 and all(_LABEL_RE.fullmatch(x) for x in h.split("."))


def _san(hosts: tuple[str, ...]) -> x509.SubjectAlternativeName:
    names: list[x509.GeneralName] = []
    for h in hosts:
        try:
            names.append(x509.IPAddress(ipaddress.ip_address(h)))
        except ValueError:
            names.append(x509.DNSName(h))
    return x509.SubjectAlternativeName(names)


def issue(directory: str | Path, name: str, role: str, hosts: tuple[str, ...] = (),
          days: int = 825, not_before: dt.datetime | None = None) -> tuple[Path, Path]:
    """Sign a certificate for peer ``name`` of ``role``: ``NAME.crt`` and ``NAME.key``
    (0600) in ``directory``. Its SANs are localhost, 127.0.0.1, ::1 and ``hosts`` (the
    addresses others dial it at, for a router or a listening shovel)."""
    d = Path(directory)
    if not keys.NAME.fullmatch(name) or name in ("ca",):
        raise PkiError(f"name {name!r}: use 1-64 letters, digits, '_', '.', '-' (not 'ca'); "
                       "for a shovel, its shovel.id")
    if role not in ROLES:
        raise PkiError(f"role {role!r}: must be one of {list(ROLES)}")
    bad = [h for h in hosts if not _host_ok(h)]
    if bad:
        raise PkiError(f"--host {bad[0]!r}: expected an IP address or a host name (letters, "
                       "digits and '-' in dot-separated labels of 1-63 characters)")
    if not 0 < days <= 36500:
        raise PkiError(f"days must be > 0 and at most 36500, got {days}")
    ca_cert, ca_key = _load_ca(d)
    for other in list_certs(d):
        if other.common_name == name:
            raise PkiError(f"{other.path}: a certificate for {name!r} exists already "
                           "(common names must be unique: the access control goes by them)")
    key = ec.generate_private_key(ec.SECP256R1())
    org = ca_cert.subject.get_attributes_for_oid(NameOID.ORGANIZATION_NAME)
    attrs = [x509.NameAttribute(NameOID.ORGANIZATIONAL_UNIT_NAME, role),
             x509.NameAttribute(NameOID.COMMON_NAME, name)]
    if org:
        attrs.insert(0, x509.NameAttribute(NameOID.ORGANIZATION_NAME, str(org[0].value)))
    start = not_before or (_now() - dt.timedelta(minutes=5))
    all_hosts = tuple(dict.fromkeys((*DEFAULT_HOSTS, *hosts)))
    cert = (x509.CertificateBuilder().subject_name(x509.Name(attrs))
            .issuer_name(ca_cert.subject).public_key(key.public_key())
            .serial_number(x509.random_serial_number())
            .not_valid_before(start).not_valid_after(start + dt.timedelta(days=days))
            .add_extension(x509.BasicConstraints(ca=False, path_length=None), critical=True)
            .add_extension(x509.KeyUsage(digital_signature=True, content_commitment=False,
                                         key_encipherment=False, data_encipherment=False,
                                         key_agreement=False, key_cert_sign=False,
                                         crl_sign=False, encipher_only=False,
                                         decipher_only=False), critical=True)
            # every peer both dials (client) and may listen (server)
            .add_extension(x509.ExtendedKeyUsage([ExtendedKeyUsageOID.SERVER_AUTH,
                                                  ExtendedKeyUsageOID.CLIENT_AUTH]),
                           critical=False)
            .add_extension(_san(all_hosts), critical=False)
            .add_extension(x509.AuthorityKeyIdentifier.from_issuer_public_key(
                ca_key.public_key()), critical=False)
            .sign(ca_key, hashes.SHA256()))
    crt, kp = d / f"{name}.crt", d / f"{name}.key"
    _write_private(kp, _key_pem(key))
    _write_public(crt, cert.public_bytes(serialization.Encoding.PEM))
    return crt, kp


def read_cert(path: str | Path) -> CertInfo:
    """Read a PEM certificate's holder, role and dates (PkiError names the file)."""
    p = Path(path)
    try:
        data = p.read_bytes()
    except OSError as e:
        raise PkiError(f"{p}: cannot read: {e.strerror}") from None
    try:
        cert = x509.load_pem_x509_certificate(data)
    except ValueError:
        raise PkiError(f"{p}: not a PEM certificate") from None
    cn = cert.subject.get_attributes_for_oid(NameOID.COMMON_NAME)
    ou = cert.subject.get_attributes_for_oid(NameOID.ORGANIZATIONAL_UNIT_NAME)
    try:
        san = cert.extensions.get_extension_for_class(x509.SubjectAlternativeName).value
        hosts = tuple(str(v) for v in san.get_values_for_type(x509.DNSName)) + tuple(
            str(v) for v in san.get_values_for_type(x509.IPAddress))
    except x509.ExtensionNotFound:
        hosts = ()
    return CertInfo(path=p, common_name=str(cn[0].value) if cn else "",
                    role=str(ou[0].value) if ou else None,
                    not_before=cert.not_valid_before_utc, not_after=cert.not_valid_after_utc,
                    hosts=hosts)


def list_certs(directory: str | Path) -> list[CertInfo]:
    """The peer certificates issued in ``directory`` (not the CA), by name."""
    d = Path(directory)
    if not d.is_dir():
        raise PkiError(f"{d}: no such folder")
    return [read_cert(p) for p in sorted(d.glob("*.crt")) if p.name != CA_CERT]


def check_key(path: str | Path) -> None:
    """A readable PEM private key (PkiError names the file and what is wrong)."""
    p = Path(path)
    try:
        data = p.read_bytes()
    except OSError as e:
        raise PkiError(f"{p}: cannot read: {e.strerror}") from None
    try:
        serialization.load_pem_private_key(data, None)
    except (ValueError, TypeError) as e:
        raise PkiError(f"{p}: not an unencrypted PEM private key ({e})") from None


def _load_cert(path: Path) -> x509.Certificate:
    return x509.load_pem_x509_certificate(path.read_bytes())


def check_issued_by(certificate: str | Path, ca: str | Path) -> None:
    """PkiError if ``certificate`` was not signed by the CA of ``ca``: every router of
    the site refuses a certificate of another site's CA (or one made for a test), at the
    handshake, where the daemon sees only that it cannot connect. Both files have been
    read by :func:`read_cert`."""
    from cryptography.exceptions import InvalidSignature

    cert, ca_cert = _load_cert(Path(certificate)), _load_cert(Path(ca))
    try:
        cert.verify_directly_issued_by(ca_cert)
    except (ValueError, TypeError, InvalidSignature):
        raise PkiError(f"{certificate}: not signed by the site CA of {ca} (issued by "
                       f"{cert.issuer.rfc4514_string()!r}); the routers would refuse it"
                       ) from None


def check_key_of(key: str | Path, certificate: str | Path) -> None:
    """PkiError if ``key`` (a private key :func:`check_key` has read) is not the key of
    ``certificate`` (every TLS handshake would fail), or if the machine's other users may
    read or change it (who reads it can speak as this peer: owner-only, 0600, or 0640
    with the daemon's group)."""
    k = Path(key)
    priv = serialization.load_pem_private_key(k.read_bytes(), None)
    spki = serialization.Encoding.DER, serialization.PublicFormat.SubjectPublicKeyInfo
    if (priv.public_key().public_bytes(*spki)
            != _load_cert(Path(certificate)).public_key().public_bytes(*spki)):
        raise PkiError(f"{k}: not the key of {certificate} (another peer's key?); every TLS "
                       "handshake would fail")
    mode = key_mode(k)
    if mode & 0o007:
        raise PkiError(f"{k}: other users of this machine may read or change it (mode "
                       f"{mode:04o}); make it owner-only: chmod 600 (or 640 with the "
                       "daemon's group)")


def check_cert_dates(info: CertInfo, now: dt.datetime | None = None) -> None:
    """PkiError if the certificate is expired or not valid yet."""
    t = now or _now()
    if t > info.not_after:
        raise PkiError(f"{info.path}: certificate {info.common_name!r} expired on "
                       f"{info.not_after:%Y-%m-%d %H:%M} UTC")
    if t < info.not_before:
        raise PkiError(f"{info.path}: certificate {info.common_name!r} is not valid before "
                       f"{info.not_before:%Y-%m-%d %H:%M} UTC (check the clock)")


class PeerFileError(PkiError):
    """A peer's TLS file that fails :func:`check_peer_files`; ``which`` is ``"ca"``,
    ``"certificate"`` or ``"key"``, for the caller to name its own key or option."""

    def __init__(self, which: str, message: str) -> None:
        super().__init__(message)
        self.which = which


def check_peer_files(ca: str | Path, certificate: str | Path, key: str | Path,
                     dates: bool = True, holder: Callable[[CertInfo], None] | None = None
                     ) -> tuple[CertInfo, CertInfo]:
    """What a peer's TLS handshake would refuse without saying why, checked before it:
    both certificates readable and (with ``dates``) in date, the certificate the one
    ``holder`` expects (it raises PkiError if not) and signed by the site CA, the key the
    certificate's and not readable by the machine's other users. The daemon's config
    and the screens' ``--tls`` share it. Returns the CA's and the certificate's
    :class:`CertInfo`; :class:`PeerFileError` names the file."""
    infos = []
    for which, path in (("ca", ca), ("certificate", certificate)):
        try:
            info = read_cert(path)
            if dates:
                check_cert_dates(info)
        except PkiError as e:
            raise PeerFileError(which, str(e)) from None
        infos.append(info)
    try:
        if holder is not None:
            holder(infos[1])
        check_issued_by(certificate, ca)
    except PkiError as e:
        raise PeerFileError("certificate", str(e)) from None
    try:
        check_key(key)
        check_key_of(key, certificate)
    except PkiError as e:
        raise PeerFileError("key", str(e)) from None
    return infos[0], infos[1]
