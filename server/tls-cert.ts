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

/**
 * The console's own HTTPS certificate.
 *
 * - `SHOPDECK_TLS_CERT` + `SHOPDECK_TLS_KEY`: PEM files the shop provides (`loadTlsFiles`); the
 *   certificate file may hold the chain after the server's certificate.
 * - `SHOPDECK_HTTPS=1`: a certificate made here and kept in `<data folder>/tls/`
 *   (`ensureSelfSigned`), built with node:crypto alone (no dependency, no openssl binary).
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

// ---------------------------------------------------------------- DER, just what X.509 needs

function derLength(n: number): Buffer {
  if (n < 0x80) return Buffer.from([n]);
  const bytes: number[] = [];
  for (let v = n; v > 0; v = Math.floor(v / 256)) bytes.unshift(v & 0xff);
  return Buffer.from([0x80 | bytes.length, ...bytes]);
}

function tlv(tag: number, ...parts: Buffer[]): Buffer {
  const body = Buffer.concat(parts);
  return Buffer.concat([Buffer.from([tag]), derLength(body.length), body]);
}

const seq = (...parts: Buffer[]): Buffer => tlv(0x30, ...parts);
const set = (...parts: Buffer[]): Buffer => tlv(0x31, ...parts);
const octets = (b: Buffer): Buffer => tlv(0x04, b);
const utf8 = (s: string): Buffer => tlv(0x0c, Buffer.from(s, 'utf8'));
const bool = (v: boolean): Buffer => tlv(0x01, Buffer.from([v ? 0xff : 0]));
const explicit = (n: number, inner: Buffer): Buffer => tlv(0xa0 | n, inner);
const bits = (b: Buffer, unused = 0): Buffer => tlv(0x03, Buffer.from([unused]), b);

function uint(b: Buffer): Buffer {
  let i = 0;
  while (i < b.length - 1 && b[i] === 0) i++;
  const v = b.subarray(i);
  return tlv(0x02, (v[0] ?? 0) & 0x80 ? Buffer.concat([Buffer.from([0]), v]) : v);
}

function oid(dotted: string): Buffer {
  const [a = 0, b = 0, ...rest] = dotted.split('.').map(Number);
  const out = [40 * a + b];
  for (const n of rest) {
    const chunk = [n & 0x7f];
    for (let v = Math.floor(n / 128); v > 0; v = Math.floor(v / 128)) chunk.unshift(0x80 | (v & 0x7f));
    out.push(...chunk);
  }
  return tlv(0x06, Buffer.from(out));
}

/** UTCTime before 2050, GeneralizedTime from then on (RFC 5280 4.1.2.5). */
function time(d: Date): Buffer {
  const iso = d
    .toISOString()
    .replace(/\.\d+Z$/, 'Z')
    .replace(/[-:T]/g, '');
  return d.getUTCFullYear() < 2050
    ? tlv(0x17, Buffer.from(iso.slice(2), 'ascii'))
    : tlv(0x18, Buffer.from(iso, 'ascii'));
}

const OID = {
  ecdsaSha256: '1.2.840.10045.4.3.2',
  commonName: '2.5.4.3',
  organization: '2.5.4.10',
  subjectKeyId: '2.5.29.14',
  keyUsage: '2.5.29.15',
  subjectAltName: '2.5.29.17',
  basicConstraints: '2.5.29.19',
  authorityKeyId: '2.5.29.35',
  extKeyUsage: '2.5.29.37',
  serverAuth: '1.3.6.1.5.5.7.3.1',
};

function ipBytes(ip: string): Buffer | null {
  const v = isIP(ip);
  if (v === 4) return Buffer.from(ip.split('.').map(Number));
  if (v !== 6) return null;
  let text = ip.replace(/%.*$/, '');
  // An embedded IPv4 tail ("::ffff:10.0.0.1") becomes two groups.
  const v4 = /(\d+\.\d+\.\d+\.\d+)$/.exec(text);
  if (v4?.[1]) {
    const [a = 0, b = 0, c = 0, d = 0] = v4[1].split('.').map(Number);
    text = text.slice(0, -v4[1].length) + `${((a << 8) | b).toString(16)}:${((c << 8) | d).toString(16)}`;
  }
  const [head = '', tail] = text.split('::');
  const h = head ? head.split(':') : [];
  const t = tail ? tail.split(':') : [];
  const groups = tail === undefined ? h : [...h, ...Array<string>(8 - h.length - t.length).fill('0'), ...t];
  const out = Buffer.alloc(16);
  groups.forEach((g, i) => out.writeUInt16BE(parseInt(g, 16), i * 2));
  return out;
}

function altNames(names: readonly string[]): Buffer {
  return seq(
    ...names.map((n) => {
      const ip = ipBytes(n);
      return ip ? tlv(0x87, ip) : tlv(0x82, Buffer.from(n, 'ascii'));
    }),
  );
}

function extension(id: string, critical: boolean, value: Buffer): Buffer {
  return seq(oid(id), ...(critical ? [bool(true)] : []), octets(value));
}

function name(commonName: string): Buffer {
  return seq(
    set(seq(oid(OID.commonName), utf8(commonName))),
    set(seq(oid(OID.organization), utf8('Shopdeck'))),
  );
}

function keyId(spki: Buffer): Buffer {
  return createHash('sha1').update(spki).digest();
}

function pem(label: string, der: Buffer): string {
  const b64 = der.toString('base64').match(/.{1,64}/g) ?? [];
  return `-----BEGIN ${label}-----\n${b64.join('\n')}\n-----END ${label}-----\n`;
}

interface CertSpec {
  subject: Buffer;
  issuer: Buffer;
  spki: Buffer;
  notBefore: Date;
  notAfter: Date;
  extensions: Buffer[];
  signer: KeyObject;
}

function certificate(spec: CertSpec): Buffer {
  const serial = randomBytes(16);
  serial[0] = ((serial[0] ?? 0) & 0x7f) | 0x40;
  const algorithm = seq(oid(OID.ecdsaSha256));
  const tbs = seq(
    explicit(0, uint(Buffer.from([2]))),
    uint(serial),
    algorithm,
    spec.issuer,
    seq(time(spec.notBefore), time(spec.notAfter)),
    spec.subject,
    spec.spki,
    explicit(3, seq(...spec.extensions)),
  );
  return seq(tbs, algorithm, bits(sign('sha256', tbs, spec.signer)));
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
      extension(OID.basicConstraints, true, seq(bool(true), uint(Buffer.from([0])))),
      // keyCertSign, cRLSign
      extension(OID.keyUsage, true, bits(Buffer.from([0x06]), 1)),
      extension(OID.subjectKeyId, false, octets(keyId(caSpki))),
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
      extension(OID.basicConstraints, true, seq()),
      // digitalSignature
      extension(OID.keyUsage, true, bits(Buffer.from([0x80]), 7)),
      extension(OID.extKeyUsage, false, seq(oid(OID.serverAuth))),
      extension(OID.subjectAltName, false, altNames(list)),
      extension(OID.subjectKeyId, false, octets(keyId(spki))),
      extension(OID.authorityKeyId, false, seq(tlv(0x80, keyId(caSpki)))),
    ],
  });
  const ca = pem('CERTIFICATE', caDer);
  return {
    cert: pem('CERTIFICATE', der) + ca,
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
  const x = ipBytes(a);
  const y = ipBytes(b);
  return x && y ? x.equals(y) : a === b;
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
