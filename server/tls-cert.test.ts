import { spawnSync } from 'node:child_process';
import { createHash, createPrivateKey, X509Certificate } from 'node:crypto';
import { mkdtempSync, readFileSync, rmSync, writeFileSync } from 'node:fs';
import os from 'node:os';
import path from 'node:path';
import { AsnConvert } from '@peculiar/asn1-schema';
import {
  AuthorityKeyIdentifier,
  BasicConstraints,
  Certificate,
  ExtendedKeyUsage,
  id_ce_authorityKeyIdentifier,
  id_ce_basicConstraints,
  id_ce_extKeyUsage,
  id_ce_keyUsage,
  id_ce_subjectAltName,
  id_ce_subjectKeyIdentifier,
  id_kp_serverAuth,
  KeyUsage,
  KeyUsageFlags,
  SubjectAlternativeName,
  SubjectKeyIdentifier,
} from '@peculiar/asn1-x509';
import { afterAll, describe, expect, it } from 'vitest';
import {
  CA_FILE,
  CERT_FILE,
  ensureSelfSigned,
  KEY_FILE,
  makeCertificate,
  TLS_DIR,
  VALID_DAYS,
} from './tls-cert';

/**
 * The made certificates, checked against what a tablet needs to trust a local CA and the server
 * certificate it signed: Apple's requirements for TLS server certificates (iOS 13+: SHA-2, RSA ≥
 * 2048 or ECC, names in subjectAltName, extendedKeyUsage serverAuth, at most 825 days) and a CA
 * that Android and iOS install as a trusted root (basicConstraints CA:TRUE, critical; keyUsage
 * keyCertSign, cRLSign). Read with node:crypto and, structurally, with an ASN.1 parser; and,
 * where the machine has it, with `openssl verify` (a verifier that is not the one that made it).
 */

const DAY = 86_400_000;
const ECDSA_SHA256 = '1.2.840.10045.4.3.2';
const work = mkdtempSync(path.join(os.tmpdir(), 'shopdeck-tls-'));
afterAll(() => rmSync(work, { recursive: true, force: true }));

const pems = (text: string): string[] =>
  text.match(/-----BEGIN CERTIFICATE-----[\s\S]+?-----END CERTIFICATE-----\n?/g) ?? [];

function parsed(x: X509Certificate): Certificate {
  return AsnConvert.parse(x.raw, Certificate);
}

function extension<T>(cert: Certificate, id: string, type: new () => T): { critical: boolean; value: T } {
  const ext = cert.tbsCertificate.extensions?.find((e) => e.extnID === id);
  if (!ext) throw new Error(`no extension ${id}`);
  return { critical: ext.critical, value: AsnConvert.parse(ext.extnValue, type) };
}

const hex = (b: ArrayBuffer | Uint8Array): string => Buffer.from(new Uint8Array(b)).toString('hex');
const hasOpenssl = spawnSync('openssl', ['version'], { encoding: 'utf8' }).status === 0;

describe('makeCertificate', () => {
  const now = new Date('2026-03-01T12:00:00Z');
  const names = ['localhost', 'shop-pc', 'shop-pc.local', '127.0.0.1', '::1', '192.168.1.20', 'fd00::1:2'];
  const made = makeCertificate(names, now);
  const [leafPem = '', caInChain = ''] = pems(made.cert);
  const leaf = new X509Certificate(leafPem);
  const ca = new X509Certificate(made.ca);

  it('makes a chain: the server certificate, then the CA that signed it; the key is the server’s', () => {
    expect(pems(made.cert)).toHaveLength(2);
    expect(caInChain).toBe(made.ca);
    expect(leaf.checkIssued(ca)).toBe(true);
    expect(leaf.verify(ca.publicKey)).toBe(true);
    expect(ca.verify(ca.publicKey)).toBe(true);
    expect(leaf.verify(leaf.publicKey)).toBe(false);
    expect(leaf.checkPrivateKey(createPrivateKey(made.key))).toBe(true);
    expect(ca.checkPrivateKey(createPrivateKey(made.key))).toBe(false);
    expect(leaf.issuer).toBe(ca.subject);
    expect(ca.subject).toMatch(/^CN=Shopdeck local CA .+ 2026-03-01\nO=Shopdeck$/);
    expect(leaf.subject).toBe('CN=shop-pc\nO=Shopdeck');
  });

  it('the CA: CA:TRUE (critical, path length 0), keyCertSign and cRLSign (critical), a key id', () => {
    expect(ca.ca).toBe(true);
    const c = parsed(ca);
    const bc = extension(c, id_ce_basicConstraints, BasicConstraints);
    expect(bc.critical).toBe(true);
    expect(bc.value.cA).toBe(true);
    expect(bc.value.pathLenConstraint).toBe(0);
    const ku = extension(c, id_ce_keyUsage, KeyUsage);
    expect(ku.critical).toBe(true);
    expect(ku.value.toNumber()).toBe(KeyUsageFlags.keyCertSign | KeyUsageFlags.cRLSign);
    const ski = extension(c, id_ce_subjectKeyIdentifier, SubjectKeyIdentifier);
    expect(hex(ski.value.buffer)).toBe(
      createHash('sha1')
        .update(ca.publicKey.export({ type: 'spki', format: 'der' }))
        .digest('hex'),
    );
  });

  it('the server certificate: not a CA, digitalSignature, serverAuth, every name, key ids to its CA', () => {
    expect(leaf.ca).toBe(false);
    const c = parsed(leaf);
    const bc = extension(c, id_ce_basicConstraints, BasicConstraints);
    expect(bc.critical).toBe(true);
    expect(bc.value.cA).toBe(false);
    const ku = extension(c, id_ce_keyUsage, KeyUsage);
    expect(ku.critical).toBe(true);
    expect(ku.value.toNumber()).toBe(KeyUsageFlags.digitalSignature);
    expect(extension(c, id_ce_extKeyUsage, ExtendedKeyUsage).value).toEqual([id_kp_serverAuth]);
    expect(leaf.keyUsage).toEqual([id_kp_serverAuth]);
    // Names: DNS names and IP addresses (iOS ignores the common name), each as a client checks them.
    const san = extension(c, id_ce_subjectAltName, SubjectAlternativeName).value;
    expect(san.map((n) => n.dNSName ?? `ip ${n.iPAddress ?? ''}`)).toEqual([
      'localhost',
      'shop-pc',
      'shop-pc.local',
      'ip 127.0.0.1',
      'ip ::1',
      'ip 192.168.1.20',
      'ip fd00::1:2',
    ]);
    for (const dns of ['localhost', 'shop-pc', 'shop-pc.local']) expect(leaf.checkHost(dns)).toBe(dns);
    for (const ip of ['127.0.0.1', '::1', '192.168.1.20', 'fd00:0:0:0:0:0:1:2'])
      expect(leaf.checkIP(ip), ip).toBeDefined();
    expect(leaf.checkHost('example.com')).toBeUndefined();
    expect(leaf.checkIP('192.168.1.21')).toBeUndefined();
    const ski = extension(c, id_ce_subjectKeyIdentifier, SubjectKeyIdentifier).value;
    expect(hex(ski.buffer)).toBe(
      createHash('sha1')
        .update(leaf.publicKey.export({ type: 'spki', format: 'der' }))
        .digest('hex'),
    );
    const aki = extension(c, id_ce_authorityKeyIdentifier, AuthorityKeyIdentifier).value;
    const caSki = extension(parsed(ca), id_ce_subjectKeyIdentifier, SubjectKeyIdentifier).value;
    expect(aki.keyIdentifier && hex(aki.keyIdentifier.buffer)).toBe(hex(caSki.buffer));
  });

  it('ECDSA P-256 keys, signed with SHA-256, version 3, a positive 128-bit serial', () => {
    for (const x of [leaf, ca]) {
      expect(x.publicKey.asymmetricKeyType).toBe('ec');
      expect(x.publicKey.asymmetricKeyDetails?.namedCurve).toBe('prime256v1');
      const c = parsed(x);
      expect(c.signatureAlgorithm.algorithm).toBe(ECDSA_SHA256);
      expect(c.tbsCertificate.signature.algorithm).toBe(ECDSA_SHA256);
      expect(c.tbsCertificate.version).toBe(2); // v3
      expect(x.serialNumber).toMatch(/^[4-7][0-9A-F]{31}$/);
    }
    expect(leaf.serialNumber).not.toBe(ca.serialNumber);
  });

  it('valid from a day back, for at most 825 days (Apple), inside the CA’s validity', () => {
    const from = new Date(leaf.validFrom).getTime();
    const to = new Date(leaf.validTo).getTime();
    expect(from).toBe(now.getTime() - DAY);
    expect(to - from).toBe(VALID_DAYS * DAY);
    expect(to - from).toBeLessThanOrEqual(825 * DAY);
    expect(new Date(ca.validFrom).getTime()).toBeLessThanOrEqual(from);
    expect(new Date(ca.validTo).getTime()).toBeGreaterThanOrEqual(to);
  });

  it('writes dates from 2050 on as GeneralizedTime, and refuses an empty name list', () => {
    const late = new X509Certificate(makeCertificate(['localhost'], new Date('2051-06-01T00:00:00Z')).ca);
    expect(new Date(late.validFrom).toISOString()).toBe('2051-05-31T00:00:00.000Z');
    expect(parsed(late).tbsCertificate.validity.notBefore.generalTime).toBeInstanceOf(Date);
    expect(() => makeCertificate(['not a name!'])).toThrow(/at least one host name/);
  });

  it.skipIf(!hasOpenssl)('openssl verifies the chain for a TLS server and reads the same properties', () => {
    const dir = mkdtempSync(path.join(work, 'openssl-'));
    writeFileSync(path.join(dir, 'ca.pem'), made.ca);
    writeFileSync(path.join(dir, 'leaf.pem'), leafPem);
    const at = String(Math.floor(now.getTime() / 1000));
    const verify = (...args: string[]): ReturnType<typeof spawnSync> =>
      spawnSync('openssl', ['verify', '-attime', at, '-CAfile', path.join(dir, 'ca.pem'), ...args], {
        encoding: 'utf8',
      });
    const ok = verify('-purpose', 'sslserver', '-x509_strict', path.join(dir, 'leaf.pem'));
    expect(`${String(ok.stdout)}${String(ok.stderr)}`).toContain('leaf.pem: OK');
    expect(ok.status).toBe(0);
    // The CA as a root of its own, and a client certificate purpose refused (serverAuth only).
    expect(verify('-x509_strict', path.join(dir, 'ca.pem')).status).toBe(0);
    expect(verify('-purpose', 'sslclient', path.join(dir, 'leaf.pem')).status).not.toBe(0);
    // After the validity: refused.
    const late = spawnSync(
      'openssl',
      [
        'verify',
        '-attime',
        String(Math.floor(now.getTime() / 1000) + 830 * 86400),
        '-CAfile',
        path.join(dir, 'ca.pem'),
        path.join(dir, 'leaf.pem'),
      ],
      { encoding: 'utf8' },
    );
    expect(late.status).not.toBe(0);
    const text = (file: string): string =>
      spawnSync('openssl', ['x509', '-noout', '-text', '-in', path.join(dir, file)], { encoding: 'utf8' })
        .stdout;
    const caText = text('ca.pem');
    expect(caText).toMatch(/Basic Constraints: critical\s+CA:TRUE, pathlen:0/);
    expect(caText).toMatch(/Key Usage: critical\s+Certificate Sign, CRL Sign/);
    expect(caText).toContain('Signature Algorithm: ecdsa-with-SHA256');
    expect(caText).toMatch(/NIST CURVE: P-256/);
    const leafText = text('leaf.pem');
    expect(leafText).toMatch(/Basic Constraints: critical\s+CA:FALSE/);
    expect(leafText).toMatch(/Key Usage: critical\s+Digital Signature\n/);
    expect(leafText).toMatch(/Extended Key Usage: \s+TLS Web Server Authentication\n/);
    expect(leafText).toContain(
      'DNS:localhost, DNS:shop-pc, DNS:shop-pc.local, IP Address:127.0.0.1, IP Address:0:0:0:0:0:0:0:1, IP Address:192.168.1.20, IP Address:FD00:0:0:0:0:0:1:2',
    );
    expect(leafText).toMatch(/Authority Key Identifier:\s+[0-9A-F:]{59}/);
    expect(leafText).toMatch(/Subject Key Identifier:\s+[0-9A-F:]{59}/);
  });
});

describe('ensureSelfSigned', () => {
  it('makes the pair on first start, keeps it, and makes a new one when it expired', () => {
    const dataDir = mkdtempSync(path.join(work, 'data-'));
    const t0 = new Date('2026-03-01T12:00:00Z');
    const first = ensureSelfSigned(dataDir, ['localhost', '127.0.0.1'], t0);
    expect(first.made).toBe('first start');
    expect(first.missing).toEqual([]);
    expect(first.material.names).toEqual(['localhost', '127.0.0.1']);
    const dir = path.join(dataDir, TLS_DIR);
    expect(readFileSync(path.join(dir, CA_FILE), 'utf8')).toBe(first.material.ca?.pem);
    const leaf = new X509Certificate(readFileSync(path.join(dir, CERT_FILE), 'utf8'));
    expect(leaf.checkPrivateKey(createPrivateKey(readFileSync(path.join(dir, KEY_FILE), 'utf8')))).toBe(true);
    expect(leaf.fingerprint256).toBe(first.material.fingerprint);

    const kept = ensureSelfSigned(
      dataDir,
      ['localhost', '127.0.0.1', '::1'],
      new Date(t0.getTime() + 10 * DAY),
    );
    expect(kept.made).toBeNull();
    expect(kept.material.fingerprint).toBe(first.material.fingerprint);
    expect(kept.missing).toEqual(['::1']);

    const later = ensureSelfSigned(dataDir, ['localhost'], new Date(t0.getTime() + 900 * DAY));
    expect(later.made).toBe('the kept certificate expired');
    expect(later.material.fingerprint).not.toBe(first.material.fingerprint);
    expect(later.material.ca?.fingerprint).not.toBe(first.material.ca?.fingerprint);
  });

  it('compares addresses however they are written (an IPv4 tail, a zone, zeros)', () => {
    const dataDir = mkdtempSync(path.join(work, 'data-'));
    const r = ensureSelfSigned(dataDir, ['::ffff:10.0.0.1', 'fe80::1%eth0', 'fd00::1'], new Date());
    expect(r.material.names).toEqual(['0:0:0:0:0:ffff:a00:1', 'fe80:0:0:0:0:0:0:1', 'fd00:0:0:0:0:0:0:1']);
    expect(ensureSelfSigned(dataDir, ['::ffff:a00:1', 'fe80::1', 'fd00:0::1', 'fd00::2']).missing).toEqual([
      'fd00::2',
    ]);
  });
});
