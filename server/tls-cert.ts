import {
  createHash,
  createPrivateKey,
  generateKeyPairSync,
  randomBytes,
  sign,
  X509Certificate,
  type KeyObject,
} from 'node:crypto';
import { existsSync, mkdirSync, readFileSync, renameSync, statSync, writeFileSync } from 'node:fs';
import { isIP } from 'node:net';
import os from 'node:os';
import path from 'node:path';
import { AsnConvert, OctetString } from '@peculiar/asn1-schema';
import * as x509 from '@peculiar/asn1-x509';

/**
 * The console's own HTTPS certificate.
 *
 * - `SHOPDECK_TLS_CERT` + `SHOPDECK_TLS_KEY`: PEM files the shop provides (`loadTlsFiles`); the
 *   certificate file may hold the chain after the server's certificate.
 * - `SHOPDECK_HTTPS=1`: a certificate made here and kept in `<data folder>/tls/`
 *   (`ensureSelfSigned`): keys and signatures by node:crypto, the certificate's structure by
 *   @peculiar/asn1-x509 (no openssl binary).
 *
 * The made certificate is a pair: a small certificate authority ("Shopdeck local CA") that signs
 * one server certificate. A tablet trusts the CA (`shopdeck-ca.crt`: Android and iOS only accept
 * a CA certificate as a trusted root, and Firefox refuses a CA certificate used as the server's
 * own). The CA's private key is thrown away as soon as it has signed: nothing on the shop PC
 * can sign a certificate for another name that the tablets would trust, so a copied data folder
 * gives no way to impersonate other web sites to them. The price: a new certificate (expiry
 * after 820 days, a new address) means a new CA that the tablets must trust again.
 *
 * The server certificate names `localhost`, this computer's host name (and `<name>.local`),
 * 127.0.0.1, ::1, every address of this computer when it is made, and `SHOPDECK_TLS_NAMES`.
 */

export const TLS_DIR = 'tls';
export const CA_FILE = 'shopdeck-ca.crt';
export const CERT_FILE = 'server.crt';
export const KEY_FILE = 'server.key';
/** Longest validity Apple platforms accept for a server certificate from a user-trusted CA is 825 days. */
export const VALID_DAYS = 820;
const DAY = 86_400_000;

export interface TlsMaterial {
  /** PEM: the server certificate, then its chain. */
  cert: string;
  /** PEM private key. */
  key: string;
  /** SHA-256 of the server certificate (DER), "AB:CD:…" as Node and browsers show it. */
  fingerprint: string;
  validTo: Date;
  /** DNS names and IP addresses the certificate is valid for. */
  names: string[];
  source: 'files' | 'self-signed';
  certFile: string;
  keyFile: string;
  /** Self-signed: the CA a tablet trusts. */
  ca?: { pem: string; fingerprint: string; file: string };
}

export class TlsSetupError extends Error {
  constructor(message: string) {
    super(`shopdeck: ${message}`);
    this.name = 'TlsSetupError';
  }
}

// ---------------------------------------------------------------- X.509 (RFC 5280)

// The certificate's structure is @peculiar/asn1-x509's (the ASN.1 layer of @peculiar/x509, by the
// same authors); node:crypto makes the keys and signs. @peculiar/x509's own generator is not used:
// it signs only through WebCrypto (a Promise, while `ensureSelfSigned` runs inside the server's
// synchronous construction and its hourly refresh) and needs a global `reflect-metadata` polyfill.

const OID = {
  ecdsaSha256: '1.2.840.10045.4.3.2',
  commonName: '2.5.4.3',
  organization: '2.5.4.10',
};

/** An IPv6 address written one way (as WHATWG URL writes it: compressed, no IPv4 tail, no zone). */
function canonicalIp(ip: string): string {
  return isIP(ip) === 6 ? new URL(`http://[${ip.replace(/%.*$/, '')}]/`).hostname.slice(1, -1) : ip;
}

function extension(extnID: string, critical: boolean, value: object): x509.Extension {
  return new x509.Extension({ extnID, critical, extnValue: new OctetString(AsnConvert.serialize(value)) });
}

function name(commonName: string): x509.Name {
  const rdn = (type: string, text: string): x509.RelativeDistinguishedName =>
    new x509.RelativeDistinguishedName([
      new x509.AttributeTypeAndValue({ type, value: new x509.AttributeValue({ utf8String: text }) }),
    ]);
  return new x509.Name([rdn(OID.commonName, commonName), rdn(OID.organization, 'Shopdeck')]);
}

/** The key identifier of RFC 5280 4.2.1.2 (1): SHA-1 of the public key (here: of its SPKI). */
function keyId(spki: Buffer): ArrayBuffer {
  return bytes(createHash('sha1').update(spki).digest());
}

/** A Buffer's bytes as the ArrayBuffer the ASN.1 classes take. */
function bytes(b: Buffer): ArrayBuffer {
  return new Uint8Array(b).buffer;
}

interface CertSpec {
  subject: x509.Name;
  issuer: x509.Name;
  spki: Buffer;
  notBefore: Date;
  notAfter: Date;
  extensions: x509.Extension[];
  signer: KeyObject;
}

/** A v3 certificate, signed with ECDSA and SHA-256 (a DER ECDSA-Sig-Value, node:crypto's default). */
function certificate(spec: CertSpec): Buffer {
  // A positive 128-bit serial with no leading zero byte.
  const serial = randomBytes(16);
  serial[0] = ((serial[0] ?? 0) & 0x7f) | 0x40;
  const algorithm = new x509.AlgorithmIdentifier({ algorithm: OID.ecdsaSha256 });
  const tbsCertificate = new x509.TBSCertificate({
    version: x509.Version.v3,
    serialNumber: bytes(serial),
    signature: algorithm,
    issuer: spec.issuer,
    // Time: UTCTime before 2050, GeneralizedTime from then on (RFC 5280 4.1.2.5).
    validity: new x509.Validity({ notBefore: spec.notBefore, notAfter: spec.notAfter }),
    subject: spec.subject,
    subjectPublicKeyInfo: AsnConvert.parse(spec.spki, x509.SubjectPublicKeyInfo),
    extensions: new x509.Extensions(spec.extensions),
  });
  const tbs = Buffer.from(AsnConvert.serialize(tbsCertificate));
  const cert = new x509.Certificate({
    tbsCertificate,
    signatureAlgorithm: algorithm,
    signatureValue: bytes(sign('sha256', tbs, spec.signer)),
  });
  return Buffer.from(AsnConvert.serialize(cert));
}

/** Valid host names and IP addresses, lower case, without duplicates. */
export function cleanNames(names: readonly string[]): string[] {
  const out: string[] = [];
  for (const raw of names) {
    const n = raw
      .trim()
      .toLowerCase()
      .replace(/^\[|\]$/g, '');
    const ok =
      isIP(n) !== 0 ||
      /^(?=.{1,253}$)[a-z0-9*](?:[a-z0-9-]*[a-z0-9])?(?:\.[a-z0-9](?:[a-z0-9-]*[a-z0-9])?)*$/.test(n);
    if (ok && !out.includes(n)) out.push(n);
  }
  return out;
}

/** The names a certificate made now should have: this computer's names and addresses, and `extra`. */
export function defaultNames(extra: readonly string[] = []): string[] {
  const host = os.hostname().toLowerCase();
  const addresses = Object.values(os.networkInterfaces())
    .flat()
    .filter((a): a is os.NetworkInterfaceInfo => !!a && !a.internal && !a.address.startsWith('fe80:'))
    .map((a) => a.address);
  return cleanNames([
    'localhost',
    host,
    ...(host.includes('.') ? [] : [`${host}.local`]),
    '127.0.0.1',
    '::1',
    ...addresses,
    ...extra,
  ]);
}

/** A new CA and a server certificate signed by it (P-256 keys, ECDSA with SHA-256). */
export function makeCertificate(
  names: readonly string[],
  now: Date = new Date(),
  days = VALID_DAYS,
): { cert: string; key: string; ca: string } {
  const list = cleanNames(names);
  if (!list.length) throw new TlsSetupError('a certificate needs at least one host name or address');
  // A day back: a tablet whose clock is a little behind still accepts it.
  const notBefore = new Date(now.getTime() - DAY);
  const notAfter = new Date(notBefore.getTime() + days * DAY);
  const caKeys = generateKeyPairSync('ec', { namedCurve: 'P-256' });
  const caSpki = caKeys.publicKey.export({ type: 'spki', format: 'der' });
  const caName = name(`Shopdeck local CA ${os.hostname()} ${now.toISOString().slice(0, 10)}`);
  const caDer = certificate({
    subject: caName,
    issuer: caName,
    spki: caSpki,
    notBefore,
    notAfter: new Date(notAfter.getTime() + DAY),
    signer: caKeys.privateKey,
    extensions: [
      extension(
        x509.id_ce_basicConstraints,
        true,
        new x509.BasicConstraints({ cA: true, pathLenConstraint: 0 }),
      ),
      extension(
        x509.id_ce_keyUsage,
        true,
        new x509.KeyUsage(x509.KeyUsageFlags.keyCertSign | x509.KeyUsageFlags.cRLSign),
      ),
      extension(x509.id_ce_subjectKeyIdentifier, false, new x509.SubjectKeyIdentifier(keyId(caSpki))),
    ],
  });
  const keys = generateKeyPairSync('ec', { namedCurve: 'P-256' });
  const spki = keys.publicKey.export({ type: 'spki', format: 'der' });
  const der = certificate({
    subject: name(list.find((n) => isIP(n) === 0 && n !== 'localhost') ?? list[0] ?? 'shopdeck'),
    issuer: caName,
    spki,
    notBefore,
    notAfter,
    signer: caKeys.privateKey,
    extensions: [
      extension(x509.id_ce_basicConstraints, true, new x509.BasicConstraints()),
      extension(x509.id_ce_keyUsage, true, new x509.KeyUsage(x509.KeyUsageFlags.digitalSignature)),
      extension(x509.id_ce_extKeyUsage, false, new x509.ExtendedKeyUsage([x509.id_kp_serverAuth])),
      extension(
        x509.id_ce_subjectAltName,
        false,
        new x509.SubjectAlternativeName(
          list.map((n) =>
            isIP(n)
              ? new x509.GeneralName({ iPAddress: canonicalIp(n) })
              : new x509.GeneralName({ dNSName: n }),
          ),
        ),
      ),
      extension(x509.id_ce_subjectKeyIdentifier, false, new x509.SubjectKeyIdentifier(keyId(spki))),
      extension(
        x509.id_ce_authorityKeyIdentifier,
        false,
        new x509.AuthorityKeyIdentifier({ keyIdentifier: new x509.KeyIdentifier(keyId(caSpki)) }),
      ),
    ],
  });
  const ca = new X509Certificate(caDer).toString();
  return {
    cert: new X509Certificate(der).toString() + ca,
    key: keys.privateKey.export({ type: 'pkcs8', format: 'pem' }).toString(),
    ca,
  };
}

// ---------------------------------------------------------------- reading certificates

const PEM_CERT = /-----BEGIN CERTIFICATE-----[\s\S]+?-----END CERTIFICATE-----/g;

function certsOf(text: string, file: string): X509Certificate[] {
  const blocks = text.match(PEM_CERT) ?? [];
  if (!blocks.length) throw new TlsSetupError(`${file} holds no PEM certificate`);
  try {
    return blocks.map((b) => new X509Certificate(b));
  } catch (e) {
    throw new TlsSetupError(
      `${file} is not a valid certificate: ${e instanceof Error ? e.message : String(e)}`,
    );
  }
}

/** Same host name, or same address however it is written ("::1" and "0:0:0:0:0:0:0:1"). */
function sameName(a: string, b: string): boolean {
  return isIP(a) && isIP(b) ? canonicalIp(a) === canonicalIp(b) : a === b;
}

function namesOf(x: X509Certificate): string[] {
  return (x.subjectAltName ?? '')
    .split(/,\s*/)
    .map((s) => /^(?:DNS|IP Address):(.+)$/.exec(s.trim())?.[1] ?? '')
    .filter(Boolean)
    .map((s) => s.toLowerCase());
}

function readPair(
  certFile: string,
  keyFile: string,
): { cert: string; key: string; leaf: X509Certificate; chain: X509Certificate[] } {
  let cert: string;
  let key: string;
  try {
    cert = readFileSync(certFile, 'utf8');
  } catch (e) {
    throw new TlsSetupError(
      `cannot read the certificate ${certFile}: ${e instanceof Error ? e.message : String(e)}`,
    );
  }
  try {
    key = readFileSync(keyFile, 'utf8');
  } catch (e) {
    throw new TlsSetupError(
      `cannot read the private key ${keyFile}: ${e instanceof Error ? e.message : String(e)}`,
    );
  }
  const chain = certsOf(cert, certFile);
  const leaf = chain[0];
  if (!leaf) throw new TlsSetupError(`${certFile} holds no PEM certificate`);
  let privateKey: KeyObject;
  try {
    privateKey = createPrivateKey(key);
  } catch (e) {
    throw new TlsSetupError(
      `${keyFile} is not a PEM private key: ${e instanceof Error ? e.message : String(e)}`,
    );
  }
  if (!leaf.checkPrivateKey(privateKey))
    throw new TlsSetupError(`the private key ${keyFile} does not belong to the certificate ${certFile}`);
  return { cert, key, leaf, chain };
}

/** The shop's own certificate and key (`SHOPDECK_TLS_CERT`, `SHOPDECK_TLS_KEY`). */
export function loadTlsFiles(certFile: string, keyFile: string): TlsMaterial {
  const { cert, key, leaf } = readPair(certFile, keyFile);
  return {
    cert,
    key,
    fingerprint: leaf.fingerprint256,
    validTo: new Date(leaf.validTo),
    names: namesOf(leaf),
    source: 'files',
    certFile,
    keyFile,
  };
}

/** A stamp that changes when either file is replaced (to reload renewed certificates). */
export function filesStamp(...files: string[]): string {
  return files
    .map((f) => {
      try {
        const s = statSync(f);
        return `${s.mtimeMs}:${s.size}:${s.ino}`;
      } catch {
        return 'missing';
      }
    })
    .join('|');
}

function writeAtomic(file: string, text: string, mode: number): void {
  const tmp = `${file}.${process.pid}.tmp`;
  writeFileSync(tmp, text, { mode });
  renameSync(tmp, file);
}

export interface SelfSigned {
  material: TlsMaterial;
  /** Why a new certificate was made now, or null when the kept one is used. */
  made: 'first start' | 'the kept certificate expired' | null;
  /** Names asked for that the kept certificate does not have (a new address, …). */
  missing: string[];
}

/**
 * The self-signed certificate in `<dataDir>/tls/`: kept across restarts, made when there is
 * none or when the kept one has expired. A broken or half-deleted folder stops the server with
 * a message saying what to do (a certificate the tablets trust is never replaced silently).
 */
export function ensureSelfSigned(
  dataDir: string,
  names: readonly string[],
  now: Date = new Date(),
): SelfSigned {
  const dir = path.join(dataDir, TLS_DIR);
  const certFile = path.join(dir, CERT_FILE);
  const keyFile = path.join(dir, KEY_FILE);
  const caFile = path.join(dir, CA_FILE);
  const wanted = cleanNames(names);
  const hasCert = existsSync(certFile);
  const hasKey = existsSync(keyFile);
  if (hasCert !== hasKey)
    throw new TlsSetupError(
      `${hasCert ? keyFile : certFile} is missing next to ${hasCert ? certFile : keyFile}: ` +
        `restore it, or delete ${dir} to make a new certificate (the tablets must then trust the new one)`,
    );
  let made: SelfSigned['made'] = null;
  if (hasCert) {
    const { leaf } = readPair(certFile, keyFile);
    if (new Date(leaf.validTo).getTime() <= now.getTime()) made = 'the kept certificate expired';
  } else {
    made = 'first start';
  }
  if (made) {
    const fresh = makeCertificate(wanted, now);
    mkdirSync(dir, { recursive: true, mode: 0o700 });
    writeAtomic(keyFile, fresh.key, 0o600);
    writeAtomic(certFile, fresh.cert, 0o644);
    writeAtomic(caFile, fresh.ca, 0o644);
  }
  const { cert, key, leaf, chain } = readPair(certFile, keyFile);
  const caCert = chain[1] ?? null;
  if (caCert && !existsSync(caFile)) writeAtomic(caFile, caCert.toString(), 0o644);
  const have = namesOf(leaf);
  return {
    made,
    missing: wanted.filter((n) => !have.some((h) => sameName(n, h))),
    material: {
      cert,
      key,
      fingerprint: leaf.fingerprint256,
      validTo: new Date(leaf.validTo),
      names: have,
      source: 'self-signed',
      certFile,
      keyFile,
      ...(caCert ? { ca: { pem: caCert.toString(), fingerprint: caCert.fingerprint256, file: caFile } } : {}),
    },
  };
}
