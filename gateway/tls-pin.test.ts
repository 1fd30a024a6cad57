import { execFileSync } from 'node:child_process';
import { X509Certificate } from 'node:crypto';
import { existsSync, linkSync, readdirSync, readFileSync, writeFileSync } from 'node:fs';
import http from 'node:http';
import https from 'node:https';
import net, { type AddressInfo } from 'node:net';
import path from 'node:path';
import tls from 'node:tls';
import { afterEach, beforeAll, describe, expect, it } from 'vitest';
import { WebSocket } from 'ws';
import type { MachineEntry } from './machines';
import { selfSignedCert, startStub, tempDir, type Stub } from './test-util';
import {
  CertificateChanged,
  connectPinned,
  fingerprintOf,
  listPins,
  normalizeFingerprint,
  PinFileError,
  pinInfo,
  PinStore,
  type PinRecord,
} from './tls-pin';

const API_KEY = 'tc-secret-key-4711';

const cleanups: Array<() => Promise<void> | void> = [];
afterEach(async () => {
  for (const c of cleanups.splice(0).reverse()) await c();
});

function dir(): string {
  const t = tempDir();
  cleanups.push(t.cleanup);
  return t.dir;
}

interface Cert {
  key: string;
  cert: string;
  /** What `openssl x509 -fingerprint -sha256` prints after "=" */
  openssl: string;
}

/** A self-signed certificate made with openssl, with the fingerprint openssl prints for it. */
function makeCert(d: string, name: string, cn: string): Cert {
  const made = selfSignedCert(d, cn, name);
  const fp = execFileSync('openssl', ['x509', '-in', made.certFile, '-noout', '-fingerprint', '-sha256'], {
    encoding: 'utf8',
  });
  return { key: made.key, cert: made.cert, openssl: fp.trim().split('=')[1] ?? '' };
}

// The real controller and an impostor with its own self-signed certificate for the same name.
let real: Cert;
let impostor: Cert;
beforeAll(() => {
  const t = tempDir();
  try {
    real = makeCert(t.dir, 'real', 'kineticcutter');
    impostor = makeCert(t.dir, 'impostor', 'kineticcutter');
  } finally {
    t.cleanup();
  }
});

async function stub(cert: Cert): Promise<Stub> {
  const s = await startStub({ key: cert.key, cert: cert.cert });
  cleanups.push(s.close);
  return s;
}

interface Recorder {
  url: string;
  port: number;
  /** TCP connections accepted */
  connections: number;
  /** TLS handshakes the server saw complete */
  handshakes: number;
  /** Every decrypted byte any client sent */
  received: () => string;
  servernames: Array<string | false>;
  alpn: Array<string | false | null>;
}

/** A TLS server that records every byte that reaches it (and answers an HTTP request minimally). */
async function recorder(cert: Cert, host = '127.0.0.1'): Promise<Recorder> {
  const chunks: Buffer[] = [];
  const rec = { connections: 0, handshakes: 0, servernames: [], alpn: [] } as unknown as Recorder;
  const server = tls.createServer({ key: cert.key, cert: cert.cert, ALPNProtocols: ['http/1.1'] }, (sock) => {
    rec.handshakes++;
    rec.servernames.push((sock as tls.TLSSocket & { servername: string | false }).servername);
    rec.alpn.push(sock.alpnProtocol);
    sock.on('error', () => undefined);
    sock.on('data', (d: Buffer) => {
      chunks.push(d);
      if (Buffer.concat(chunks).includes('\r\n\r\n'))
        sock.end('HTTP/1.1 200 OK\r\nContent-Length: 2\r\nConnection: close\r\n\r\nok');
    });
  });
  server.on('connection', () => rec.connections++);
  await new Promise<void>((r) => server.listen(0, host, () => r()));
  rec.port = (server.address() as AddressInfo).port;
  rec.url = `https://127.0.0.1:${rec.port}`;
  rec.received = () => Buffer.concat(chunks).toString('latin1');
  cleanups.push(
    () =>
      new Promise<void>((r) => {
        server.close(() => r());
      }),
  );
  return rec;
}

function machine(extra: Partial<MachineEntry> = {}): MachineEntry {
  return {
    id: 'plasma-1',
    name: 'Plasma table',
    kind: 'touchcut',
    simulated: false,
    url: new URL('https://kineticcutter'),
    wsUrl: null,
    secrets: { apiKey: API_KEY },
    ...extra,
  };
}

/** An HTTP request over a socket from connectPinned, the way the proxy is meant to use it. */
function get(socket: tls.TLSSocket, url: string): Promise<{ status: number; body: string }> {
  const u = new URL(url);
  return new Promise((resolve, reject) => {
    const req = http.request(
      {
        host: u.hostname,
        port: u.port,
        path: u.pathname,
        headers: { 'X-TouchCut-API-Key': API_KEY },
        createConnection: () => socket,
      },
      (res) => {
        const c: Buffer[] = [];
        res.on('data', (d: Buffer) => c.push(d));
        res.on('end', () =>
          resolve({ status: res.statusCode ?? 0, body: Buffer.concat(c).toString('utf8') }),
        );
      },
    );
    req.on('error', reject);
    req.end();
  });
}

/** Opens a WebSocket over a socket from connectPinned; resolves with the first message. */
function wsFirst(socket: tls.TLSSocket, url: string): Promise<{ ws: WebSocket; first: string }> {
  return new Promise((resolve, reject) => {
    const ws = new WebSocket(url, {
      headers: { 'X-TouchCut-API-Key': API_KEY },
      createConnection: () => socket,
    });
    ws.once('message', (d) => resolve({ ws, first: String(d) }));
    ws.once('error', reject);
  });
}

async function rejection(p: Promise<unknown>): Promise<Error> {
  try {
    await p;
  } catch (e) {
    return e as Error;
  }
  throw new Error('it connected');
}

describe('fingerprints', () => {
  it('normalises 64 hex digits with or without colons, any case, to the fingerprint256 form', () => {
    const upper = real.openssl;
    expect(upper).toMatch(/^([0-9A-F]{2}:){31}[0-9A-F]{2}$/);
    expect(normalizeFingerprint(upper)).toBe(upper);
    expect(normalizeFingerprint(upper.toLowerCase())).toBe(upper);
    expect(normalizeFingerprint(upper.replace(/:/g, '').toLowerCase())).toBe(upper);
    expect(normalizeFingerprint(`  ${upper}\n`)).toBe(upper);
    for (const bad of [
      '',
      upper.slice(3), // 31 pairs
      upper.replace(/:/g, '').slice(2), // 62 digits
      upper.replace(/^../, 'ZZ'),
      upper.replace(/:/, '-'),
      upper.replace(/:/g, '').replace(/^(.{2})/, '$1:'), // one colon only
      `${upper}:00`,
    ]) {
      expect(normalizeFingerprint(bad), bad).toBeNull();
    }
  });

  it('fingerprintOf is the SHA-256 of the DER, as openssl and Node print it', () => {
    const x = new X509Certificate(real.cert);
    expect(fingerprintOf({ raw: x.raw })).toBe(real.openssl);
    expect(fingerprintOf({ raw: x.raw })).toBe(x.fingerprint256);
    expect(real.openssl).not.toBe(impostor.openssl);
  });
});

describe('PinStore', () => {
  it('is empty without a file, persists as JSON, and is read back by a new store', () => {
    const d = dir();
    const s = new PinStore(d);
    expect(s.get('plasma-1')).toBeNull();
    expect(s.list()).toEqual([]);
    expect(existsSync(path.join(d, 'tls-pins.json'))).toBe(false);
    const rec = s.remember('plasma-1', {
      fingerprint: real.openssl.toLowerCase(),
      subject: 'CN=kineticcutter',
      validTo: '2030-01-01T00:00:00.000Z',
    });
    expect(rec.fingerprint).toBe(real.openssl);
    expect(Date.now() - Date.parse(rec.firstSeen)).toBeLessThan(5000);
    const onDisk = JSON.parse(readFileSync(path.join(d, 'tls-pins.json'), 'utf8')) as Record<
      string,
      PinRecord
    >;
    expect(onDisk).toEqual({
      'plasma-1': {
        fingerprint: real.openssl,
        firstSeen: rec.firstSeen,
        subject: 'CN=kineticcutter',
        validTo: '2030-01-01T00:00:00.000Z',
      },
    });
    const again = new PinStore(d);
    expect(again.get('plasma-1')).toEqual(rec);
    again.remember('a-router', { fingerprint: impostor.openssl, firstSeen: '2025-01-01T00:00:00.000Z' });
    expect(again.list().map((p) => p.id)).toEqual(['a-router', 'plasma-1']);
    // The first store sees the other one's write (the file changed on disk).
    expect(s.get('a-router')?.fingerprint).toBe(impostor.openssl);
  });

  it('keeps the first pin: the same fingerprint is a no-op, another one needs forget()', () => {
    const s = new PinStore(dir());
    const first = s.remember('plasma-1', {
      fingerprint: real.openssl,
      firstSeen: '2025-01-01T00:00:00.000Z',
    });
    expect(s.remember('plasma-1', { fingerprint: real.openssl })).toEqual(first);
    expect(() => s.remember('plasma-1', { fingerprint: impostor.openssl })).toThrow(/already pinned.*forget/);
    expect(s.get('plasma-1')?.fingerprint).toBe(real.openssl);
    expect(s.forget('plasma-1')).toEqual(first);
    expect(s.forget('plasma-1')).toBeNull();
    expect(s.get('plasma-1')).toBeNull();
    expect(s.remember('plasma-1', { fingerprint: impostor.openssl }).fingerprint).toBe(impostor.openssl);
    expect(() => s.remember('Plasma 1', { fingerprint: real.openssl })).toThrow(/not a machine id/);
    expect(() => s.remember('plasma-2', { fingerprint: 'abc' })).toThrow(/not a SHA-256/);
  });

  it('writes atomically: a new file is renamed over the old one, no temporary file is left', () => {
    const d = dir();
    const s = new PinStore(d);
    s.remember('plasma-1', { fingerprint: real.openssl });
    // A hard link shares the old file's inode: writing in place would change it too.
    const link = path.join(d, 'old-copy.json');
    linkSync(s.file, link);
    const before = readFileSync(link, 'utf8');
    s.remember('router', { fingerprint: impostor.openssl });
    expect(readFileSync(link, 'utf8')).toBe(before);
    expect(readFileSync(s.file, 'utf8')).toContain('"router"');
    s.forget('plasma-1');
    expect(readdirSync(d).sort()).toEqual(['old-copy.json', 'tls-pins.json']);
  });

  it('refuses a corrupt file everywhere and never overwrites it', () => {
    const d = dir();
    const file = path.join(d, 'tls-pins.json');
    const cases: Array<[string, RegExp]> = [
      ['{"plasma-1": {"fingerprint": "AA:BB"', /not JSON/],
      ['', /not JSON/],
      ['[]', /expected an object/],
      [
        `{"plasma-1": {"fingerprint": "${real.openssl.toLowerCase()}", "firstSeen": "x"}}`,
        /"plasma-1\.fingerprint"/,
      ],
      [`{"plasma-1": {"firstSeen": "x"}}`, /"plasma-1\.fingerprint"/],
      [`{"__proto__": {"fingerprint": "${real.openssl}", "firstSeen": "x"}}`, /not a machine id/],
    ];
    for (const [text, why] of cases) {
      writeFileSync(file, text);
      const s = new PinStore(d);
      for (const call of [
        () => s.get('plasma-1'),
        () => s.list(),
        () => s.remember('plasma-1', { fingerprint: impostor.openssl }),
        () => s.forget('plasma-1'),
      ]) {
        let err: unknown;
        try {
          call();
        } catch (e) {
          err = e;
        }
        expect(err, text).toBeInstanceOf(PinFileError);
        expect((err as Error).message).toMatch(why);
        expect((err as Error).message).toContain(file);
        expect((err as Error).message).toMatch(/no TLS controller is trusted until it is fixed/);
      }
      expect(readFileSync(file, 'utf8')).toBe(text);
    }
    // Repaired by hand: used at once, without a restart.
    const s = new PinStore(d);
    writeFileSync(file, '{}');
    expect(s.list()).toEqual([]);
  });
});

describe('connectPinned', () => {
  it('trusts the first certificate (TOFU), remembers it, and the request reaches the controller', async () => {
    const s = await stub(real);
    const store = new PinStore(dir());
    const trusted: Array<PinRecord & { id: string }> = [];
    const m = machine({ url: new URL(s.url) });
    const sock = await connectPinned({
      machine: m,
      url: new URL(s.url),
      store,
      onTrust: (r) => trusted.push(r),
    });
    expect(await get(sock, `${s.url}/rest/v1/status`)).toEqual({
      status: 200,
      body: JSON.stringify({ ok: true, path: '/rest/v1/status' }),
    });
    expect(s.seen.map((x) => [x.url, x.headers['x-touchcut-api-key']])).toEqual([
      ['/rest/v1/status', API_KEY],
    ]);
    expect(trusted).toHaveLength(1);
    expect(trusted[0]).toMatchObject({
      id: 'plasma-1',
      fingerprint: real.openssl,
      subject: 'CN=kineticcutter',
    });
    const pin = store.get('plasma-1');
    expect(pin?.fingerprint).toBe(real.openssl);
    // One day of validity (openssl -days 1).
    expect(Date.parse(pin?.validTo ?? '') - Date.now()).toBeGreaterThan(23 * 3600_000);
    expect(Date.parse(pin?.validTo ?? '') - Date.now()).toBeLessThan(25 * 3600_000);
    // The second connection is checked against the pin, not trusted again.
    const sock2 = await connectPinned({
      machine: m,
      url: new URL(s.url),
      store,
      onTrust: (r) => trusted.push(r),
    });
    expect((await get(sock2, `${s.url}/x`)).status).toBe(200);
    expect(trusted).toHaveLength(1);
    expect(s.seen).toHaveLength(2);
  });

  it('with a wrong pin, no byte reaches the impostor: no request line, no API key', async () => {
    const store = new PinStore(dir());
    store.remember('plasma-1', { fingerprint: real.openssl });
    const fake = await recorder(impostor);
    const m = machine({ url: new URL(fake.url) });

    // Control: what the gateway did before (rejectUnauthorized: false) hands the key over, and
    // the recorder sees it. So an empty recording below means nothing was sent.
    await new Promise<void>((resolve, reject) => {
      const req = https.request(
        {
          host: '127.0.0.1',
          port: fake.port,
          path: '/rest/v1/status',
          rejectUnauthorized: false,
          headers: { 'X-TouchCut-API-Key': API_KEY },
        },
        (res) => {
          res.resume();
          res.on('end', () => resolve());
        },
      );
      req.on('error', reject);
      req.end();
    });
    expect(fake.received()).toContain(`X-TouchCut-API-Key: ${API_KEY}`);
    const controlConnections = fake.connections;
    const controlBytes = fake.received().length;

    // Used as the proxy uses it: connect, then send the request with the key on that socket.
    const err = await rejection(
      connectPinned({ machine: m, url: new URL(fake.url), store }).then((sock) =>
        get(sock, `${fake.url}/rest/v1/status`),
      ),
    );
    expect(err).toBeInstanceOf(CertificateChanged);
    const cc = err as CertificateChanged;
    // `got` is the impostor's certificate: the TLS handshake with it did take place.
    expect(cc).toMatchObject({
      machineId: 'plasma-1',
      expected: real.openssl,
      got: impostor.openssl,
      source: 'pinned',
    });
    expect(cc.message).toBe(
      `the certificate of Plasma table (plasma-1) changed: expected ${real.openssl}, got ${impostor.openssl} — ` +
        `if the controller was replaced or re-keyed, a supervisor accepts the new certificate ` +
        `(Supervisor › TLS certificates › Forget, i.e. DELETE /api/tls/plasma-1; the next connection trusts the certificate it is shown); ` +
        `otherwise someone may be impersonating it. Nothing was sent to it.`,
    );
    await new Promise((r) => setTimeout(r, 100));
    // The impostor was reached, but not one byte of data followed the handshake.
    expect(fake.connections).toBe(controlConnections + 1);
    expect(fake.received().length).toBe(controlBytes);
    // The pin is unchanged.
    expect(store.get('plasma-1')?.fingerprint).toBe(real.openssl);
  });

  it('an https stub with the impostor certificate records no request and no socket', async () => {
    const store = new PinStore(dir());
    store.remember('plasma-1', { fingerprint: real.openssl });
    const fake = await stub(impostor);
    await expect(
      connectPinned({ machine: machine(), url: new URL(fake.url), store }).then((sock) =>
        get(sock, `${fake.url}/rest/v1/status`),
      ),
    ).rejects.toBeInstanceOf(CertificateChanged);
    await expect(
      connectPinned({ machine: machine(), url: new URL(`${fake.wsUrl}/live`), store }).then((sock) =>
        wsFirst(sock, `${fake.wsUrl}/live`),
      ),
    ).rejects.toBeInstanceOf(CertificateChanged);
    await new Promise((r) => setTimeout(r, 100));
    expect(fake.seen).toEqual([]);
    expect(fake.wsSeen).toEqual([]);
  });

  it('a configured tlsFingerprint wins over the pin file and is never stored', async () => {
    const s = await stub(real);
    const fake = await recorder(impostor);
    const d = dir();
    const store = new PinStore(d);
    const m = machine({ tlsFingerprint: real.openssl.replace(/:/g, '').toLowerCase() });
    const sock = await connectPinned({ machine: m, url: new URL(s.url), store });
    expect((await get(sock, `${s.url}/status`)).status).toBe(200);
    expect(existsSync(store.file)).toBe(false);

    const err = await rejection(connectPinned({ machine: m, url: new URL(fake.url), store }));
    expect(err).toBeInstanceOf(CertificateChanged);
    expect(err).toMatchObject({ source: 'configured', expected: real.openssl, got: impostor.openssl });
    expect(err.message).toMatch(/field "tlsFingerprint" of "plasma-1"/);
    expect(err.message).toMatch(/impersonating/);
    expect(fake.received()).toBe('');
    expect(existsSync(store.file)).toBe(false);

    // A stale TOFU pin of the impostor does not matter once the fingerprint is configured.
    store.remember('plasma-1', { fingerprint: impostor.openssl });
    const sock2 = await connectPinned({ machine: m, url: new URL(s.url), store });
    expect((await get(sock2, `${s.url}/status`)).status).toBe(200);
  });

  it('after forget(), the next connection trusts the certificate it is shown', async () => {
    const fake = await recorder(impostor);
    const store = new PinStore(dir());
    store.remember('plasma-1', { fingerprint: real.openssl });
    await expect(connectPinned({ machine: machine(), url: new URL(fake.url), store })).rejects.toBeInstanceOf(
      CertificateChanged,
    );
    store.forget('plasma-1');
    const sock = await connectPinned({ machine: machine(), url: new URL(fake.url), store });
    expect((await get(sock, `${fake.url}/x`)).status).toBe(200);
    expect(store.get('plasma-1')?.fingerprint).toBe(impostor.openssl);
  });

  it('a corrupt pin file refuses the connection before anything is sent, and is kept', async () => {
    const fake = await recorder(real);
    const d = dir();
    const store = new PinStore(d);
    writeFileSync(store.file, '{ broken');
    const err = await rejection(connectPinned({ machine: machine(), url: new URL(fake.url), store }));
    expect(err).toBeInstanceOf(PinFileError);
    await new Promise((r) => setTimeout(r, 100));
    expect(fake.connections).toBe(1);
    expect(fake.received()).toBe('');
    expect(readFileSync(store.file, 'utf8')).toBe('{ broken');
  });

  it('works with the ws package: createConnection gets the checked socket', async () => {
    const s = await stub(real);
    const store = new PinStore(dir());
    const sock = await connectPinned({ machine: machine(), url: new URL(`${s.wsUrl}/live`), store });
    const ws = new WebSocket(`${s.wsUrl}/live`, {
      headers: { 'X-TouchCut-API-Key': API_KEY },
      createConnection: () => sock,
    });
    cleanups.push(() => ws.terminate());
    const messages: string[] = [];
    await new Promise<void>((resolve, reject) => {
      ws.on('message', (d) => {
        messages.push(String(d));
        if (messages.length === 1) ws.send('ping');
        if (messages.length === 2) resolve();
      });
      ws.on('error', reject);
    });
    expect(messages).toEqual(['hello', 'echo:ping']);
    expect(s.wsSeen.map((x) => [x.url, x.headers['x-touchcut-api-key']])).toEqual([['/live', API_KEY]]);
    expect(store.get('plasma-1')?.fingerprint).toBe(real.openssl);
    await new Promise<void>((r) => {
      ws.once('close', () => r());
      ws.close();
    });
  });

  it('sends SNI for a host name (not for an IP) and offers http/1.1 by ALPN', async () => {
    const fake = await recorder(real, '::');
    const store = new PinStore(dir());
    const byName = await connectPinned({
      machine: machine(),
      url: new URL(`https://localhost:${fake.port}`),
      store,
    });
    expect((await get(byName, `https://localhost:${fake.port}/`)).status).toBe(200);
    const byIp = await connectPinned({ machine: machine(), url: new URL(fake.url), store });
    expect((await get(byIp, `${fake.url}/`)).status).toBe(200);
    expect(fake.servernames).toEqual(['localhost', false]);
    expect(fake.alpn).toEqual(['http/1.1', 'http/1.1']);
  });

  it('gives up after the connect timeout when the handshake never completes', async () => {
    const sockets: net.Socket[] = [];
    let closed = 0;
    const silent = net.createServer((c) => {
      sockets.push(c);
      c.resume();
      c.on('close', () => closed++);
    });
    await new Promise<void>((r) => silent.listen(0, '127.0.0.1', () => r()));
    cleanups.push(
      () =>
        new Promise<void>((r) => {
          for (const c of sockets) c.destroy();
          silent.close(() => r());
        }),
    );
    const port = (silent.address() as AddressInfo).port;
    const t0 = Date.now();
    const err = await rejection(
      connectPinned({
        machine: machine(),
        url: new URL(`https://127.0.0.1:${port}`),
        store: new PinStore(dir()),
        timeoutMs: 200,
      }),
    );
    expect(err.message).toMatch(/timed out after 200 ms/);
    expect(Date.now() - t0).toBeGreaterThanOrEqual(190);
    expect(Date.now() - t0).toBeLessThan(5000);
    await new Promise((r) => setTimeout(r, 100));
    expect(closed).toBe(1);
  });

  it('refuses a non-TLS address and reports connection errors', async () => {
    const store = new PinStore(dir());
    await expect(
      connectPinned({ machine: machine(), url: new URL('http://127.0.0.1:1'), store }),
    ).rejects.toThrow(/not a TLS address/);
    const closed = net.createServer();
    await new Promise<void>((r) => closed.listen(0, '127.0.0.1', () => r()));
    const port = (closed.address() as AddressInfo).port;
    await new Promise<void>((r) => closed.close(() => r()));
    await expect(
      connectPinned({ machine: machine(), url: new URL(`https://127.0.0.1:${port}`), store }),
    ).rejects.toThrow(/ECONNREFUSED/);
    expect(store.list()).toEqual([]);
  });
});

describe('pinInfo / listPins (GET /api/tls)', () => {
  it('lists machines reached over TLS with the fingerprint in force, and no address', () => {
    const store = new PinStore(dir());
    store.remember('plasma-1', {
      fingerprint: real.openssl,
      subject: 'CN=kineticcutter',
      firstSeen: '2025-05-01T00:00:00.000Z',
    });
    store.remember('plasma-2', { fingerprint: impostor.openssl, firstSeen: '2025-05-01T00:00:00.000Z' });
    const machines: MachineEntry[] = [
      machine(),
      machine({ id: 'plasma-2', name: 'Plasma 2', tlsFingerprint: real.openssl }),
      machine({ id: 'plasma-3', name: 'Plasma 3' }),
      machine({ id: 'router', name: 'Router', kind: 'g2core', url: new URL('http://10.0.0.12:8080') }),
      machine({
        id: 'laser',
        name: 'Laser',
        kind: 'xtool',
        url: new URL('http://10.0.0.50'),
        wsUrl: new URL('wss://10.0.0.50:8081'),
      }),
      machine({ id: 'sim', name: 'Sim', simulated: true }),
    ];
    const list = listPins(machines, store);
    expect(list).toEqual([
      {
        id: 'plasma-1',
        name: 'Plasma table',
        mode: 'pinned',
        fingerprint: real.openssl,
        pin: {
          fingerprint: real.openssl,
          subject: 'CN=kineticcutter',
          firstSeen: '2025-05-01T00:00:00.000Z',
        },
        canForget: true,
      },
      {
        id: 'plasma-2',
        name: 'Plasma 2',
        mode: 'configured',
        fingerprint: real.openssl,
        pin: { fingerprint: impostor.openssl, firstSeen: '2025-05-01T00:00:00.000Z' },
        canForget: false,
      },
      { id: 'plasma-3', name: 'Plasma 3', mode: 'unpinned', fingerprint: null, pin: null, canForget: false },
      { id: 'laser', name: 'Laser', mode: 'unpinned', fingerprint: null, pin: null, canForget: false },
    ]);
    expect(JSON.stringify(list)).not.toMatch(/kineticcutter\/|10\.0\.0|https?:|wss?:/);
    expect(pinInfo(machines[3]!, store)).toBeNull();
    expect(pinInfo(machines[5]!, store)).toBeNull();
  });
});

describe('no connection to a controller skips the certificate check but the pinned one', () => {
  /** Product source (tests and test rigs aside), comments removed. */
  function productSources(): Array<{ file: string; code: string }> {
    const out: Array<{ file: string; code: string }> = [];
    const walk = (dir: string): void => {
      for (const e of readdirSync(dir, { withFileTypes: true })) {
        const p = path.join(dir, e.name);
        if (e.isDirectory()) {
          if (e.name !== 'node_modules' && !e.name.startsWith('.')) walk(p);
        } else if (/\.(ts|tsx|mjs)$/.test(e.name) && !/\.test\.|test-util|testkit|\.d\.ts$/.test(e.name)) {
          const code = readFileSync(p, 'utf8')
            .replace(/\/\*[\s\S]*?\*\//g, '')
            .replace(/(^|[^:])\/\/.*$/gm, '$1');
          out.push({ file: path.relative(process.cwd(), p).split(path.sep).join('/'), code });
        }
      }
    };
    for (const d of ['gateway', 'server', 'src', 'scripts']) walk(path.resolve(d));
    return out;
  }

  it('only tls-pin.ts turns Node’s own check off (its pin replaces it); no agent or option elsewhere does', () => {
    const files = productSources();
    expect(files.length).toBeGreaterThan(50);
    const skipping = files
      .filter(({ code }) =>
        /rejectUnauthorized\s*:\s*(false|0|!|null|undefined)|NODE_TLS_REJECT_UNAUTHORIZED|checkServerIdentity/.test(
          code,
        ),
      )
      .map((f) => f.file);
    expect(skipping).toEqual(['gateway/tls-pin.ts']);
  });
});
